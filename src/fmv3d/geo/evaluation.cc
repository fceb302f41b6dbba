#include "fmv3d/geo/evaluation.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/dsm.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

namespace {

struct Stats {
  double sum = 0, sq = 0;
  size_t n = 0;
  void Add(double v) { sum += v, sq += v * v, ++n; }
  double Rms() const { return n ? std::sqrt(sq / n) : 0; }
  double Mean() const { return n ? sum / n : 0; }
  double CentredRms() const { return n ? std::sqrt(std::max(0.0, sq / n - Mean() * Mean())) : 0; }
};

// The modelled area: truth.json's "bounds" (world frame of the truth); empty when it states none.
Eigen::AlignedBox3d ModelledRegion(const nlohmann::json& truth) {
  if (!truth.contains("bounds")) return {};
  const auto lo = truth["bounds"].at("min").get<std::vector<double>>(),
             hi = truth["bounds"].at("max").get<std::vector<double>>();
  if (lo.size() != 3 || hi.size() != 3) return {};
  return {Eigen::Vector3d(lo[0], lo[1], lo[2]), Eigen::Vector3d(hi[0], hi[1], hi[2])};
}

// DSM height errors over a set of compared cells: e = DSM − truth, its part that is the reconstruction's own
// (e_model) and georef's predicted height σ there.
struct DsmTally {
  Stats dz, dz_model, expected;
  std::vector<double> abs_dz;
  void Add(double e, double e_model, std::optional<double> sigma) {
    dz.Add(e), dz_model.Add(e_model), abs_dz.push_back(std::abs(e));
    if (sigma) expected.Add(*sigma);
  }
  double Percentile(double q) {
    if (abs_dz.empty()) return 0.0;
    const size_t k = std::min(abs_dz.size() - 1, static_cast<size_t>(q * abs_dz.size()));
    std::nth_element(abs_dz.begin(), abs_dz.begin() + k, abs_dz.end());
    return abs_dz[k];
  }
  nlohmann::json ToJson(double building) {
    return {{"cells_compared", dz.n},
            {"height_rms_m", dz.Rms()},
            {"height_bias_m", dz.Mean()},
            {"abs_error_p50_m", Percentile(0.5)},
            {"abs_error_p90_m", Percentile(0.9)},
            {"height_rms_of_model_m", dz_model.Rms()},
            {"height_rms_of_model_percent_of_building", 100 * dz_model.Rms() / building},
            {"height_rms_without_bias_m", dz.CentredRms()},
            {"height_rms_percent_of_building", 100 * dz.Rms() / building},
            {"height_rms_without_bias_percent_of_building", 100 * dz.CentredRms() / building},
            {"expected_height_rms_from_georef_m", expected.n ? nlohmann::json(expected.Rms()) : nlohmann::json()}};
  }
};

// Absolute error of the georeferenced reconstruction over the true surface. The model's shape is tied to the
// truth by its cameras: S = the least-squares similarity of geo/sparse_enu/'s camera centres onto the true
// ones (both in the workspace's ENU frame). A true surface point X then sits in the georeferenced model at
// S⁻¹(X) — what the model (and every product made from it) states for X — and |S⁻¹(X) − X| is its absolute
// error, sampled uniformly over the true mesh inside truth.json's "bounds" (the modelled area, not synth's
// backdrop ring), whether or not the reconstruction has a point there. This isolates the georeference
// (translation, rotation, scale) from the dense/sparse surface noise, which "points" and "dsm" measure.
// S: the least-squares similarity of the georeferenced cameras onto the true ones (workspace ENU); *fit_rms its
// residual RMS.
template <typename ToWs>
core::Sim3 GeorefErrorSimilarity(const core::Reconstruction& est, const core::Reconstruction& tru, const ToWs& to_ws,
                                 double* fit_rms) {
  std::vector<Eigen::Vector3d> src, dst;
  std::vector<std::pair<const core::Image*, const core::Image*>> matched;
  for (const auto& [id, img] : est.images)
    if (const core::Image* t = tru.FindImageByName(img.name)) {
      src.push_back(img.pose.Centre()), dst.push_back(to_ws(t->pose.Centre()));
      matched.emplace_back(&img, t);
    }
  // Centres on a nearly straight line leave the roll about it free (the fit would pick it from their noise):
  // then each camera also contributes a point one track length along its optical axis, so the cameras'
  // orientations fix the roll.
  if (src.size() >= 3) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : dst) mean += p;
    mean /= static_cast<double>(dst.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : dst) cov += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov / static_cast<double>(dst.size()));
    const double along = std::sqrt(std::max(0.0, eig.eigenvalues()(2))),
                 lateral = std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
    if (lateral < 0.05 * along) {
      const double reach = 2 * along;
      for (const auto& [e, t] : matched) {
        src.push_back(e->pose.Centre() + reach * (e->pose.q.conjugate() * Eigen::Vector3d::UnitZ()));
        dst.push_back(to_ws(t->pose.Centre() + reach * (t->pose.q.conjugate() * Eigen::Vector3d::UnitZ())));
      }
    }
  }
  core::Sim3 s;
  if (src.size() < 3 || !geometry::EstimateSimilarity(src, dst, &s))
    throw Error("evaluate-geo: fewer than 3 non-collinear cameras match the truth; no surface error");
  Stats fit;
  for (size_t i = 0; i < matched.size(); ++i) fit.Add((s.Apply(src[i]) - dst[i]).norm());  // the centres
  *fit_rms = fit.Rms();
  return s;
}

template <typename ToWs>
nlohmann::json SurfaceError(const core::Reconstruction& est, const core::Reconstruction& tru, const core::Sim3& s,
                            double fit_rms, const io::TexturedMesh& mesh, const nlohmann::json& truth,
                            const ToWs& to_ws, const std::optional<GeorefAccuracy>& accuracy) {
  const Eigen::AlignedBox3d region = ModelledRegion(truth);
  std::vector<Eigen::Vector3i> tris;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d c = (mesh.vertices[f.v[0]] + mesh.vertices[f.v[1]] + mesh.vertices[f.v[2]]) / 3.0;
    if (region.isEmpty() || region.contains(c)) tris.emplace_back(f.v[0], f.v[1], f.v[2]);
  }
  if (tris.empty()) throw Error("evaluate-geo: no triangle of the true mesh inside truth.json's bounds");
  const geometry::MeshDistance surface(mesh.vertices, tris);  // the truth's frame
  // About 50k samples whatever the scene's size; kept where at least 2 of the registered cameras (at their true
  // poses) have the sample in their field of view — the part of the world the reconstruction is about.
  double area = 0;
  for (size_t f = 0; f < surface.num_triangles(); ++f) area += surface.Area(static_cast<int>(f));
  std::vector<const core::Image*> views;
  for (const auto& [id, img] : est.images)
    if (const core::Image* t = tru.FindImageByName(img.name)) views.push_back(t);
  const core::Sim3 inv = s.Inverse();
  Stats e3, eh, ev, expected;  // expected: the height σ georef predicts at the sample (geo/accuracy.h)
  const bool predict = accuracy && accuracy->rotation_known;
  double worst = 0;
  size_t all = 0;
  for (const auto& x : surface.SampleSurface(std::max(0.05, std::sqrt(area / 5e4)), nullptr, 11)) {
    ++all;
    int seen = 0;
    for (const core::Image* v : views) {
      const Eigen::Vector3d xc = v->pose.Transform(x);
      if (xc.z() > 0 && tru.cameras.at(v->camera_id).InImage(tru.cameras.at(v->camera_id).Project(xc)) && ++seen >= 2)
        break;
    }
    if (seen < 2) continue;
    const Eigen::Vector3d xw = to_ws(x), d = inv.Apply(xw) - xw;
    e3.Add(d.norm()), eh.Add(d.head<2>().norm()), ev.Add(d.z());
    if (predict) expected.Add(accuracy->HeightSigma(xw - accuracy->pivot));
    worst = std::max(worst, d.norm());
  }
  if (e3.n == 0) throw Error("evaluate-geo: no sample of the true mesh is in view of 2 registered cameras");
  nlohmann::json j = {
      {"samples", e3.n},
      {"samples_in_region", all},
      {"region", std::string(region.isEmpty() ? "whole mesh" : "truth.json bounds") +
                     ", in the field of view of >= 2 registered cameras (true poses; no occlusion test)"},
      {"rms_m", e3.Rms()},
      {"horizontal_rms_m", eh.Rms()},
      {"vertical_rms_m", ev.Rms()},
      {"vertical_mean_m", ev.Mean()},
      {"max_m", worst},
      {"cameras_fit_rms_m", fit_rms},
      // The georeference's own error, as S: its rotation, the part of it that tilts the vertical, scale.
      {"rotation_error_deg", Eigen::AngleAxisd(s.q).angle() * 180 / M_PI},
      {"tilt_error_deg", std::acos(std::clamp((s.q * Eigen::Vector3d::UnitZ()).z(), -1.0, 1.0)) * 180 / M_PI},
      {"scale_error", s.s - 1},
      {"maps",
       "error of true point X = S^-1(X) - X, S = similarity of geo/sparse_enu camera centres onto the true ones"}};
  // What georef expected of the vertical here (1σ RMS over the same samples), beside what it got.
  j["expected_vertical_rms_m"] = predict ? nlohmann::json(expected.Rms()) : nlohmann::json();
  return j;
}

// The truth's frame (synth's geo origin) to the workspace's ENU frame.
struct TruthToWorkspace {
  const LocalFrame& fg;
  const LocalFrame& ft;
  Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return fg.ToEnu(ft.ToGeodetic(x)); }
};

// Camera centres of geo/sparse_enu against the true ones; `bias` gets their mean offset.
nlohmann::json CameraErrors(const core::Reconstruction& est, const core::Reconstruction& tru,
                            const TruthToWorkspace& to_ws, const std::string& ws_name, Eigen::Vector3d& bias) {
  Stats c3, ch, cv_;
  bias.setZero();
  for (const auto& [id, img] : est.images) {
    const core::Image* t = tru.FindImageByName(img.name);
    if (!t) continue;
    const Eigen::Vector3d d = img.pose.Centre() - to_ws(t->pose.Centre());
    c3.Add(d.norm());
    ch.Add(d.head<2>().norm());
    cv_.Add(d.z());
    bias += d;
  }
  if (c3.n == 0) throw Error(ws_name + ": no camera of geo/sparse_enu matches the truth by name");
  bias /= static_cast<double>(c3.n);
  return {{"matched", c3.n},
          {"centre_rms_m", c3.Rms()},
          {"horizontal_rms_m", ch.Rms()},
          {"vertical_rms_m", cv_.Rms()},
          {"bias_enu_m", {bias.x(), bias.y(), bias.z()}},
          {"bias_m", bias.norm()}};
}

// Telemetry positions against the true camera centres: per-axis RMS and the mean error (`mean`), the floor a
// position-only georeference cannot see past.
struct TelemetryErrors {
  Stats x, y, z;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  void Add(const Eigen::Vector3d& d) {
    x.Add(d.x()), y.Add(d.y()), z.Add(d.z());
    sum += d;
  }
  Eigen::Vector3d Mean() const { return x.n ? Eigen::Vector3d(sum / static_cast<double>(x.n)) : sum; }
  nlohmann::json ToJson(const char* count_name) const {
    const Eigen::Vector3d mean = Mean();
    return {{count_name, x.n},
            {"error_rms_per_axis_m", {x.Rms(), y.Rms(), z.Rms()}},
            {"mean_error_enu_m", {mean.x(), mean.y(), mean.z()}},
            {"mean_error_m", mean.norm()}};
  }
};

// The telemetry of each keyframe (frames.json) against its true camera.
TelemetryErrors FrameTelemetryErrors(const io::FramesIndex& index, const core::Reconstruction& tru,
                                     const LocalFrame& fg, const TruthToWorkspace& to_ws, bool msl) {
  TelemetryErrors e;
  for (const auto& f : index.frames) {
    const core::Image* t = tru.FindImageByName(f.name);
    if (!t || !f.telemetry || !f.telemetry->sensor_latitude || !f.telemetry->sensor_longitude) continue;
    const auto& tel = *f.telemetry;
    const std::optional<double> alt =
        !msl && tel.sensor_altitude_hae ? tel.sensor_altitude_hae : tel.sensor_altitude_msl;
    if (!alt) continue;
    const GeoPoint p{*tel.sensor_latitude, *tel.sensor_longitude, *alt};
    e.Add(fg.ToEnu(p) - to_ws(t->pose.Centre()));
  }
  return e;
}

// Every packet of frames/telemetry.json against the true camera of its frame (synth writes one packet per frame,
// at its time).
TelemetryErrors TrackTelemetryErrors(const fs::path& track_json, double fps, const core::Reconstruction& tru,
                                     const LocalFrame& fg, const TruthToWorkspace& to_ws, bool msl) {
  TelemetryErrors e;
  for (const auto& track : telemetry::ReadTelemetryTracks(track_json))
    for (const auto& s : track.samples) {
      const double k = std::round(s.time * fps);
      if (std::abs(s.time * fps - k) > 0.01 || !s.sensor_latitude || !s.sensor_longitude) continue;
      const std::optional<double> alt = !msl && s.sensor_altitude_hae ? s.sensor_altitude_hae : s.sensor_altitude_msl;
      const core::Image* t = tru.FindImageByName(fmt::format("flight-{:06d}.png", static_cast<long long>(k)));
      if (!t || !alt) continue;
      e.Add(fg.ToEnu({*s.sensor_latitude, *s.sensor_longitude, *alt}) - to_ws(t->pose.Centre()));
    }
  return e;
}

// Sparse points against the true mesh (already in the workspace frame).
nlohmann::json PointErrors(const core::Reconstruction& est, const geometry::MeshDistance& dist, double building) {
  Stats pd, ps;
  std::vector<double> all;
  for (const auto& [id, p] : est.points) {
    const auto c = dist.Closest(p.xyz);
    pd.Add(c.distance);
    if (c.distance < 0.05 * building) ps.Add(c.signed_distance);  // the bias of the points near the surface
    all.push_back(c.distance);
  }
  std::sort(all.begin(), all.end());
  return {{"count", pd.n},
          {"rms_m", pd.Rms()},
          {"median_m", all.empty() ? 0.0 : all[all.size() / 2]},
          {"signed_mean_m", ps.Mean()},
          {"signed_mean_of", "points within 5% of H of the true mesh; + outside"}};
}

// The lowest and highest true height over a disc of radius k cells around each cell; a cell without truth (NaN)
// in the disc makes them ∓inf.
void TruthRangeOverDisc(const cv::Mat& th, int k, cv::Mat& t_min, cv::Mat& t_max) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  t_min = th.clone();
  t_max = th.clone();
  t_min.setTo(-kInf, th != th);
  t_max.setTo(kInf, th != th);
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * k + 1, 2 * k + 1));
  cv::erode(t_min, t_min, disc, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, -kInf);
  cv::dilate(t_max, t_max, disc, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, kInf);
}

// The DSM against the true mesh rasterised on its grid; writes report/dsm_error.png.
nlohmann::json DsmErrors(const core::Workspace& ws, const fs::path& dsm_path, const io::TexturedMesh& mesh,
                         const nlohmann::json& truth, double building, const Georef& g, const LocalFrame& fg,
                         const LocalFrame& ft, const core::Sim3& s_inv) {
  GridSpec grid;
  const cv::Mat h = ReadHeightGeoTiff(dsm_path, &grid);
  UtmSurface ts;
  ts.vertices = mesh.vertices;
  fg.EnuToUtm(&ts.vertices);
  for (const auto& f : mesh.faces) ts.triangles.emplace_back(f.v[0], f.v[1], f.v[2]);
  const cv::Mat th = RasteriseDsm(ts, grid);
  // Cells are compared where the true surface is flat (within 1% of H) over a disc of radius `margin`
  // (3% of H, at least one cell) around them. A height step (a wall) has no single true height in its cell,
  // and the cells beside it take the wall's full height from any horizontal offset of the reconstruction
  // (the georeference alone is ~0.5 m off horizontally) or from the mesh rounding the wall's foot: there a
  // height difference measures the offset, not the DSM's heights (the usual breakline exclusion).
  const double flat = std::max(0.01 * building, 0.05);
  const double margin = std::max(grid.gsd, 0.03 * building);
  cv::Mat t_min, t_max;
  TruthRangeOverDisc(th, static_cast<int>(std::ceil(margin / grid.gsd)), t_min, t_max);
  // Two tallies: the modelled area (truth.json's bounds: the terrain tile and buildings, the region of the
  // surface figure) and every compared cell, which adds synth's backdrop: a far-ground ring of quarter-tile
  // facets, 0.3 m below the terrain at its vertices and flat between them, with blurred, hazy texture (it is
  // there so oblique views see land). Its seam with the tile is a step of synth's own making, and its land is
  // made not to be matched. The headline is the modelled area, as for the surface.
  const Eigen::AlignedBox3d region = ModelledRegion(truth);
  const Eigen::AlignedBox2d modelled =
      region.isEmpty() ? Eigen::AlignedBox2d() : Eigen::AlignedBox2d(region.min().head<2>(), region.max().head<2>());
  DsmTally in_area, all_cells;
  size_t seen = 0;
  // Signed error per compared cell, for dsm_error.png: blue below the truth, red above, full colour at 1% of
  // the building height; grey where seen but not compared (near a height step), black where unseen.
  cv::Mat err_png(h.rows, h.cols, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int r = 0; r < h.rows; ++r)
    for (int c = 0; c < h.cols; ++c) {
      const float v = h.at<float>(r, c);
      if (!std::isfinite(v)) continue;
      ++seen;
      err_png.at<cv::Vec3b>(r, c) = cv::Vec3b(96, 96, 96);
      const float lo = t_min.at<float>(r, c), hi = t_max.at<float>(r, c);
      if (!std::isfinite(lo) || !std::isfinite(hi) || hi - lo > flat) continue;
      const double e = v - th.at<float>(r, c);
      // The part of e that is the reconstruction's own (not the georeference's): minus the height error S⁻¹
      // makes at this true surface point.
      const Eigen::Vector2d en = grid.CellCentre(r, c);
      const Eigen::Vector3d xw = fg.ToEnu(fg.UtmToGeodetic({en.x(), en.y(), th.at<float>(r, c)}));
      const double e_model = e - (s_inv.Apply(xw) - xw).z();
      std::optional<double> expected;
      if (g.accuracy && g.accuracy->rotation_known) expected = g.accuracy->HeightSigma(xw - g.accuracy->pivot);
      all_cells.Add(e, e_model, expected);
      if (modelled.isEmpty() || modelled.contains(Eigen::Vector2d(ft.ToEnu(fg.ToGeodetic(xw)).head<2>())))
        in_area.Add(e, e_model, expected);
      const double t = std::clamp(e / (0.01 * building), -1.0, 1.0);
      const auto lift = [](double a) { return static_cast<uchar>(255 * (1 - std::abs(a))); };
      err_png.at<cv::Vec3b>(r, c) = t < 0 ? cv::Vec3b(255, lift(t), lift(t)) : cv::Vec3b(lift(t), lift(t), 255);
    }
  core::EnsureDirectory(ws.report_dir());
  core::WriteAtomically(ws.report_dir() / "dsm_error.png", [&](const fs::path& tmp) {
    if (!cv::imwrite(tmp.string() + ".png", err_png))
      throw Error((ws.report_dir() / "dsm_error.png").string() + ": cannot write");
    fs::rename(tmp.string() + ".png", tmp);
  });
  nlohmann::json j = in_area.ToJson(building);
  j.update({{"cells_seen", seen},
            {"region", modelled.isEmpty() ? "whole DSM (truth.json has no bounds)"
                                          : "truth.json bounds (the modelled area, as for the surface)"},
            {"flat_tolerance_m", flat},
            {"step_margin_m", margin},
            {"compared", "cells whose true surface is flat within flat_tolerance_m over a disc of step_margin_m"},
            {"error_map", "report/dsm_error.png (blue below, red above the truth, saturated at 1% of H)"}});
  j["whole_seen"] = all_cells.ToJson(building);
  j["whole_seen"]["region"] = "every compared cell, synth's far-ground backdrop included";
  return j;
}

}  // namespace

nlohmann::json EvaluateGeoAgainstSynth(const core::Workspace& ws, const fs::path& synth) {
  const nlohmann::json truth = core::ReadJson(synth / "truth.json");
  if (!truth.contains("geo_origin"))
    throw Error((synth / "truth.json").string() + ": no geo_origin (render the flight with `fmv3d synth --klv`)");
  GeoPoint to{truth["geo_origin"]["lat"].get<double>(), truth["geo_origin"]["lon"].get<double>(),
              truth["geo_origin"]["alt"].get<double>()};
  const double building = truth.at("characteristic_length").get<double>();
  const Georef g = ReadGeoref(ws);
  // A workspace whose heights are MSL (telemetry without ellipsoidal heights, e.g. EXIF): the truth's origin is
  // ellipsoidal, so it is lowered by the geoid undulation there (constant over a survey: EGM96 changes by
  // centimetres per kilometre), and the telemetry is read at MSL.
  const bool msl = g.datum == VerticalDatum::kMsl;
  if (msl) {
    const std::optional<double> n = GeoidUndulation(to.lat, to.lon);
    if (!n) throw Error(ws.name() + ": heights are MSL but the EGM96 geoid grid is not available to compare them");
    to.alt -= *n;
  }
  const LocalFrame fg(g.origin, g.utm), ft(to, g.utm);
  const TruthToWorkspace to_ws{fg, ft};

  nlohmann::json j;
  j["building_height_m"] = building;
  j["vertical_datum"] = msl ? "MSL (truth lowered by the EGM96 undulation at its origin)" : "WGS84 ellipsoid";
  const core::Reconstruction est = io::ReadColmapText(ws.sparse_enu_dir());
  const core::Reconstruction tru = io::ReadColmapText(synth / "truth");
  Eigen::Vector3d bias;
  j["cameras"] = CameraErrors(est, tru, to_ws, ws.name(), bias);
  // The floor set by the telemetry itself: the mean of (telemetry − true) camera positions, which a
  // position-only georeference cannot see past (its translation error tends to exactly this).
  if (fs::exists(ws.frames_json())) {
    const TelemetryErrors e = FrameTelemetryErrors(io::ReadFramesIndex(ws.frames_json()), tru, fg, to_ws, msl);
    if (e.x.n) {
      j["telemetry"] = e.ToJson("frames");
      j["cameras"]["bias_minus_telemetry_mean_m"] = (bias - e.Mean()).norm();
    }
  }
  // The same floor for a georeference fitted on every packet (frames/telemetry.json).
  if (fs::exists(ws.telemetry_json()) && truth.contains("fps")) {
    const TelemetryErrors e =
        TrackTelemetryErrors(ws.telemetry_json(), truth["fps"].get<double>(), tru, fg, to_ws, msl);
    if (e.x.n) {
      j["telemetry_track"] = e.ToJson("packets");
      j["cameras"]["bias_minus_track_mean_m"] = (bias - e.Mean()).norm();
    }
  }
  io::TexturedMesh mesh = io::ReadObj(synth / "scene.obj", false);
  double fit_rms = 0;
  const core::Sim3 s_err = GeorefErrorSimilarity(est, tru, to_ws, &fit_rms);
  j["surface"] = SurfaceError(est, tru, s_err, fit_rms, mesh, truth, to_ws, g.accuracy);
  for (auto& v : mesh.vertices) v = to_ws(v);
  j["points"] = PointErrors(est, geometry::MeshDistance(mesh), building);
  const fs::path dsm_path = ws.geo_dir() / "dsm.tif";
  if (fs::exists(dsm_path)) j["dsm"] = DsmErrors(ws, dsm_path, mesh, truth, building, g, fg, ft, s_err.Inverse());
  return j;
}

}  // namespace fmv3d::geo
