#include "fmv3d/geo/georef.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/klv_st0601_writer.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

void GeorefOptions::Check() const {
  if (min_cameras < 3) throw Error("georef: at least 3 cameras are needed");
  if (max_samples < 1) throw Error("georef: max_samples must be positive");
  if (!(min_inlier_threshold > 0)) throw Error("georef: min_inlier_threshold must be positive");
  if (origin && !(std::abs(origin->lat) <= 90 && std::abs(origin->lon) <= 180 && std::isfinite(origin->alt)))
    throw Error(fmt::format("georef: bad origin {}, {}, {}", origin->lat, origin->lon, origin->alt));
}

namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  return v[m];
}

std::vector<double> Residuals(const core::Sim3& s, const std::vector<Eigen::Vector3d>& src,
                              const std::vector<Eigen::Vector3d>& dst) {
  std::vector<double> r(src.size());
  for (size_t i = 0; i < src.size(); ++i) r[i] = (s.Apply(src[i]) - dst[i]).norm();
  return r;
}

nlohmann::json SimJson(const core::Sim3& s) {
  const Eigen::Matrix3d R = s.q.toRotationMatrix();
  const Eigen::Matrix4d M = s.Matrix();
  nlohmann::json j;
  j["scale"] = s.s;
  j["rotation_wxyz"] = {s.q.w(), s.q.x(), s.q.y(), s.q.z()};
  j["rotation"] = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) j["rotation"].push_back({R(r, 0), R(r, 1), R(r, 2)});
  j["translation"] = {s.t.x(), s.t.y(), s.t.z()};
  j["matrix"] = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) j["matrix"].push_back({M(r, 0), M(r, 1), M(r, 2), M(r, 3)});
  j["maps"] = "X_enu = scale * R * X_sparse + translation";
  return j;
}

// Unit normal of the best-fit plane of the points (smallest principal axis), pointing towards `above`.
std::optional<Eigen::Vector3d> GroundNormal(const core::Reconstruction& rec, const Eigen::Vector3d& above) {
  if (rec.points.size() < 10) return std::nullopt;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [id, p] : rec.points) mean += p.xyz;
  mean /= static_cast<double>(rec.points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& [id, p] : rec.points) cov += (p.xyz - mean) * (p.xyz - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3d n = eig.eigenvectors().col(0);
  if (n.dot(above - mean) < 0) n = -n;
  return n;
}

// Rotates the similarity about the (ENU) line through `centre` along `axis` so that the model's ground
// normal maps as close to +z (up) as possible: fixes the roll that collinear camera positions leave free.
core::Sim3 LevelAboutAxis(const core::Sim3& sim, const Eigen::Vector3d& axis, const Eigen::Vector3d& centre,
                          const Eigen::Vector3d& model_normal) {
  const Eigen::Vector3d d = axis.normalized();
  const Eigen::Vector3d v = sim.q * model_normal, z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d vp = v - v.dot(d) * d, zp = z - z.dot(d) * d;
  if (vp.norm() < 1e-9 || zp.norm() < 1e-9) return sim;
  const double angle = std::atan2(vp.cross(zp).dot(d), vp.dot(zp));
  const Eigen::Quaterniond fix(Eigen::AngleAxisd(angle, d));
  core::Sim3 out;
  out.s = sim.s;
  out.q = (fix * sim.q).normalized();
  out.t = fix * (sim.t - centre) + centre;  // X' = fix (sim(X) - c) + c
  return out;
}

// Similarity of two point sets along a line (the source collinear): the direction, scale and centroid are fitted;
// the roll about the line is left at the minimal rotation (the caller levels it).
bool LineSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                    core::Sim3* sim) {
  const size_t n = src.size();
  Eigen::Vector3d cs = Eigen::Vector3d::Zero(), cd = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) cs += src[i], cd += dst[i];
  cs /= static_cast<double>(n), cd /= static_cast<double>(n);
  auto axis = [](const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3d& c) {
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& x : p) cov += (x - c) * (x - c).transpose();
    return Eigen::Vector3d(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvectors().col(2));
  };
  const Eigen::Vector3d us = axis(src, cs);
  Eigen::Vector3d ud = axis(dst, cd);
  double sxy = 0, sxx = 0;
  for (size_t i = 0; i < n; ++i) {
    const double a = (src[i] - cs).dot(us), b = (dst[i] - cd).dot(ud);
    sxy += a * b, sxx += a * a;
  }
  if (!(sxx > 0) || sxy == 0) return false;
  if (sxy < 0) ud = -ud, sxy = -sxy;
  sim->s = sxy / sxx;
  sim->q = Eigen::Quaterniond::FromTwoVectors(us, ud);
  sim->t = cd - sim->s * (sim->q * cs);
  return true;
}

double Collinearity(const std::vector<Eigen::Vector3d>& p) {  // second / first principal spread
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& x : p) c += x;
  c /= static_cast<double>(p.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& x : p) cov += (x - c) * (x - c).transpose();
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();
  return ev(2) > 0 ? std::sqrt(std::max(0.0, ev(1)) / ev(2)) : 0;
}

Eigen::Vector3d LogRotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// Telemetry camera-to-ENU rotation of a frame with the full ST 0601 angle chain, else nullopt.
std::optional<Eigen::Matrix3d> TelemetryAttitude(const nlohmann::json& t) {
  const char* keys[] = {"platform_heading", "platform_pitch", "platform_roll", "sensor_relative_azimuth",
                        "sensor_relative_elevation", "sensor_relative_roll"};
  for (const char* k : keys)
    if (!t.contains(k) || !t[k].is_number()) return std::nullopt;
  io::klv::St0601Attitude a;
  a.platform_heading = t["platform_heading"].get<double>();
  a.platform_pitch = t["platform_pitch"].get<double>();
  a.platform_roll = t["platform_roll"].get<double>();
  a.sensor_relative_azimuth = t["sensor_relative_azimuth"].get<double>();
  a.sensor_relative_elevation = t["sensor_relative_elevation"].get<double>();
  a.sensor_relative_roll = t["sensor_relative_roll"].get<double>();
  return io::klv::CameraToEnuFromSt0601(a);
}

}  // namespace

core::Sim3 RobustSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                            const GeorefOptions& o, std::vector<char>* inliers, double* sigma_out) {
  const size_t n = src.size();
  if (n < 3 || dst.size() != n) throw Error(fmt::format("georef: {} camera/telemetry pairs, at least 3 needed", n));
  // Least median of squares over minimal samples: no inlier threshold to guess, tolerates < 50% outliers.
  std::mt19937_64 rng(o.seed);
  core::Sim3 best;
  double best_med = std::numeric_limits<double>::infinity();
  // Every triple for small sets, else random ones (seeded: deterministic).
  std::vector<std::array<size_t, 3>> triples;
  if (n <= 14) {
    for (size_t a = 0; a < n; ++a)
      for (size_t b = a + 1; b < n; ++b)
        for (size_t c = b + 1; c < n; ++c) triples.push_back({a, b, c});
  } else {
    for (int it = 0; it < o.max_samples; ++it) {
      const size_t a = rng() % n;
      size_t b = rng() % n, c = rng() % n;
      while (b == a) b = rng() % n;
      while (c == a || c == b) c = rng() % n;
      triples.push_back({a, b, c});
    }
  }
  for (const auto& [a, b, c] : triples) {
    core::Sim3 s;
    if (!geometry::EstimateSimilarity({src[a], src[b], src[c]}, {dst[a], dst[b], dst[c]}, &s)) continue;
    if (!(s.s > 0) || !std::isfinite(s.s)) continue;
    const double med = Median(Residuals(s, src, dst));
    if (med < best_med) best_med = med, best = s;
  }
  if (!std::isfinite(best_med) && Collinearity(src) < 1e-3) {  // a straight model track: fit along the line
    for (const auto& [a, b, c] : triples) {
      core::Sim3 s;
      if (!LineSimilarity({src[a], src[b], src[c]}, {dst[a], dst[b], dst[c]}, &s)) continue;
      const double med = Median(Residuals(s, src, dst));
      if (med < best_med) best_med = med, best = s;
    }
  }
  if (!std::isfinite(best_med)) throw Error("georef: no similarity could be fitted (degenerate camera positions)");
  const bool line = Collinearity(src) < 1e-3;
  // Per-axis sigma from the median 3D residual (the median of a 3-dof chi is 1.538 σ, with Rousseeuw & Leroy's
  // small-sample correction), then inliers within 3.5 σ (≈ the 99% quantile of the 3D norm), refit, repeat.
  double sigma = (1 + 5.0 / std::max<double>(1, n - 3)) * best_med / 1.538;
  std::vector<char> mask(n, 1);
  core::Sim3 sim = best;
  for (int round = 0; round < 3; ++round) {
    const double thr = std::max(o.min_inlier_threshold, 3.5 * sigma);
    const auto r = Residuals(sim, src, dst);
    std::vector<Eigen::Vector3d> s_in, d_in;
    for (size_t i = 0; i < n; ++i) {
      mask[i] = r[i] <= thr;
      if (mask[i]) s_in.push_back(src[i]), d_in.push_back(dst[i]);
    }
    core::Sim3 refit;
    if (s_in.size() < 3 || !(line ? LineSimilarity(s_in, d_in, &refit) : geometry::EstimateSimilarity(s_in, d_in, &refit)))
      break;
    sim = refit;
    std::vector<double> rin;
    for (size_t i = 0; i < n; ++i)
      if (mask[i]) rin.push_back((sim.Apply(src[i]) - dst[i]).norm());
    double sq = 0;
    for (double v : rin) sq += v * v;
    sigma = std::sqrt(sq / (3.0 * std::max<double>(1, rin.size() - 7.0 / 3)));  // per axis (7 dof fitted)
  }
  if (inliers) *inliers = mask;
  if (sigma_out) *sigma_out = sigma;
  return sim;
}

Georef ReadGeoref(const fs::path& ws) {
  const fs::path p = ws / "geo" / "georef.json";
  if (!fs::exists(p)) throw Error(ws.string() + ": no geo/georef.json — run `fmv3d georef` first");
  const nlohmann::json j = core::ReadJson(p);
  try {
    Georef g;
    g.origin = {j.at("origin").at("lat").get<double>(), j.at("origin").at("lon").get<double>(),
                j.at("origin").at("alt").get<double>()};
    g.vertical_datum = j.value("vertical_datum", "");
    const auto& s = j.at("similarity");
    g.sparse_to_enu.s = s.at("scale").get<double>();
    const auto q = s.at("rotation_wxyz").get<std::vector<double>>();
    const auto t = s.at("translation").get<std::vector<double>>();
    if (q.size() != 4 || t.size() != 3) throw Error("bad similarity");
    g.sparse_to_enu.q = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized();
    g.sparse_to_enu.t = Eigen::Vector3d(t[0], t[1], t[2]);
    g.utm.zone = j.at("utm").at("zone").get<int>();
    g.utm.north = j.at("utm").at("north").get<bool>();
    if (g.utm.zone < 1 || g.utm.zone > 60 || !(g.sparse_to_enu.s > 0)) throw Error("bad values");
    return g;
  } catch (const std::exception& e) {
    throw Error(p.string() + ": malformed georef (" + e.what() + ") — run `fmv3d georef` again");
  }
}

nlohmann::json RunGeorefStage(const fs::path& ws, const GeorefOptions& o) {
  o.Check();
  const fs::path frames_json = ws / "frames" / "frames.json", sparse = ws / "sparse";
  if (!fs::exists(frames_json)) throw Error(ws.string() + ": no frames/frames.json — run `fmv3d frames` first");
  if (!fs::exists(sparse / "images.txt")) throw Error(ws.string() + ": no sparse/ model — run `fmv3d sparse` first");
  const io::FramesIndex index = io::ReadFramesIndex(frames_json);
  core::Reconstruction rec = io::ReadColmapText(sparse);

  // Pairs (model camera centre, telemetry position). Heights: ellipsoidal when every used frame states it.
  struct Pair {
    std::string name;
    Eigen::Vector3d centre;
    GeoPoint pos;
    const nlohmann::json* telemetry = nullptr;
  };
  std::vector<Pair> pairs;
  size_t with_telemetry = 0, hae = 0;
  for (const auto& f : index.frames) {
    const auto& t = f.telemetry;
    if (!t.is_object() || !t.contains("sensor_latitude") || !t.contains("sensor_longitude")) continue;
    if (!t.contains("sensor_altitude_hae") && !t.contains("sensor_altitude_msl")) continue;
    ++with_telemetry;
    const core::Image* img = rec.FindImageByName(f.name);
    if (!img) continue;
    Pair p;
    p.name = f.name;
    p.centre = img->pose.Centre();
    p.pos.lat = t.at("sensor_latitude").get<double>();
    p.pos.lon = t.at("sensor_longitude").get<double>();
    p.telemetry = &t;
    if (t.contains("sensor_altitude_hae")) ++hae;
    pairs.push_back(p);
  }
  if (with_telemetry == 0)
    throw Error(frames_json.string() + ": no frame carries a telemetry position (georef needs KLV, DJI SRT or GPS)");
  if (static_cast<int>(pairs.size()) < o.min_cameras)
    throw Error(fmt::format("georef: only {} registered frames have telemetry positions ({} needed)", pairs.size(),
                            o.min_cameras));
  const bool use_hae = hae == pairs.size();  // else MSL for all: one vertical datum for every frame
  for (auto& p : pairs) p.pos.alt = p.telemetry->at(use_hae ? "sensor_altitude_hae" : "sensor_altitude_msl").get<double>();

  GeoPoint origin;
  if (o.origin) {
    origin = *o.origin;
  } else {  // centroid of the positions (mean in ECEF through a provisional frame, exact for any spread)
    const LocalFrame provisional(pairs.front().pos);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pairs) mean += provisional.ToEnu(p.pos);
    origin = provisional.ToGeodetic(mean / static_cast<double>(pairs.size()));
  }
  const LocalFrame frame(origin);
  std::vector<Eigen::Vector3d> src, dst;
  for (const auto& p : pairs) src.push_back(p.centre), dst.push_back(frame.ToEnu(p.pos));
  std::vector<char> inliers;
  double sigma = 0;
  core::Sim3 sim = RobustSimilarity(src, dst, o, &inliers, &sigma);
  // A nearly straight track fixes only the rotation's axis along it: the roll about the track comes from the
  // model's ground plane, which must be level in ENU.
  std::string roll_source = "camera positions";
  {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : dst) mean += p;
    mean /= static_cast<double>(dst.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : dst) cov += (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    const double lateral_sd = std::sqrt(std::max(0.0, eig.eigenvalues()(1)) / dst.size());
    const double along_sd = std::sqrt(std::max(0.0, eig.eigenvalues()(2)) / dst.size());
    if (lateral_sd < std::max(sigma, 0.05 * along_sd)) {  // no sideways spread beyond the noise
      Eigen::Vector3d model_above = Eigen::Vector3d::Zero();
      for (const auto& c : src) model_above += c;
      const auto normal = GroundNormal(rec, model_above / static_cast<double>(src.size()));
      if (!normal)
        throw Error("georef: the camera positions lie nearly on a line and the model has too few points to find "
                    "the ground: the rotation about the track is unknown (fly a curve or an orbit)");
      sim = LevelAboutAxis(sim, eig.eigenvectors().col(2), mean, *normal);
      roll_source = "ground plane of the sparse points (nearly straight track)";
      spdlog::warn("georef: nearly straight track; the roll about it is taken from the level ground plane");
    }
  }

  // Telemetry attitude (sensor angles of every inlier frame) as a second, independent measurement of the
  // rotation: each frame gives R ≈ R_telemetry · R_model⁻¹. Positions constrain a rotation by their spread
  // (information Σ [d]ₓᵀ[d]ₓ / σ²), the attitudes by their count over their scatter (N / σₐ²); the two are
  // fused in the information form and s, t refitted for the fused rotation. Skipped (with a note) when the
  // two disagree beyond their uncertainties, e.g. an attitude convention the source does not follow.
  nlohmann::json attitude_json = {{"used", false}};
  if (roll_source == "camera positions") {
    std::vector<Eigen::Matrix3d> rel;
    for (size_t i = 0; i < pairs.size(); ++i) {
      if (!inliers[i]) continue;
      const auto ra = TelemetryAttitude(*pairs[i].telemetry);
      if (!ra) continue;
      const core::Image* img = rec.FindImageByName(pairs[i].name);
      rel.push_back(*ra * img->pose.R());  // camera-to-ENU · model-to-camera = model-to-ENU rotation
    }
    if (rel.size() >= 3) {
      // Chordal mean, then the scatter about it.
      Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
      for (const auto& r : rel) sum += r;
      Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
      Eigen::Matrix3d r_att = svd.matrixU() * svd.matrixV().transpose();
      if (r_att.determinant() < 0) {
        Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
        d(2, 2) = -1;
        r_att = svd.matrixU() * d * svd.matrixV().transpose();
      }
      double sq = 0;
      for (const auto& r : rel) sq += LogRotation(r * r_att.transpose()).squaredNorm();
      const double sigma_att = std::max(1e-4, std::sqrt(sq / (3.0 * rel.size())));  // rad per axis
      const Eigen::Matrix3d r_pos = sim.q.toRotationMatrix();
      const Eigen::Vector3d w_att = LogRotation(r_att * r_pos.transpose());  // world-frame correction
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      size_t n_in = 0;
      for (size_t i = 0; i < dst.size(); ++i)
        if (inliers[i]) mean += dst[i], ++n_in;
      mean /= static_cast<double>(n_in);
      Eigen::Matrix3d info_pos = Eigen::Matrix3d::Zero();
      for (size_t i = 0; i < dst.size(); ++i) {
        if (!inliers[i]) continue;
        const Eigen::Vector3d d = sim.Apply(src[i]) - mean;
        Eigen::Matrix3d dx;
        dx << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
        info_pos += dx.transpose() * dx / (sigma * sigma);
      }
      const Eigen::Matrix3d info_att = Eigen::Matrix3d::Identity() * (rel.size() / (sigma_att * sigma_att));
      const Eigen::Matrix3d cov_diff = info_pos.inverse() + info_att.inverse();
      const double chi2 = w_att.dot(cov_diff.inverse() * w_att);
      attitude_json = {{"used", false},
                       {"frames", rel.size()},
                       {"scatter_deg", sigma_att * 180 / M_PI},
                       {"disagreement_deg", w_att.norm() * 180 / M_PI},
                       {"chi2", chi2}};
      if (chi2 < 16.3 && info_pos.allFinite()) {  // 99.9% of a 3-dof chi²
        const Eigen::Vector3d w = (info_pos + info_att).inverse() * info_att * w_att;
        const Eigen::Matrix3d R = Eigen::AngleAxisd(w.norm(), w.norm() > 0 ? w.normalized() : Eigen::Vector3d::UnitZ())
                                      .toRotationMatrix() * r_pos;
        // Scale and translation for this rotation (least squares on the inliers).
        Eigen::Vector3d ms = Eigen::Vector3d::Zero(), md = Eigen::Vector3d::Zero();
        for (size_t i = 0; i < src.size(); ++i)
          if (inliers[i]) ms += src[i], md += dst[i];
        ms /= static_cast<double>(n_in), md /= static_cast<double>(n_in);
        double num = 0, den = 0;
        for (size_t i = 0; i < src.size(); ++i)
          if (inliers[i]) num += (dst[i] - md).dot(R * (src[i] - ms)), den += (src[i] - ms).squaredNorm();
        if (den > 0 && num > 0) {
          sim.q = Eigen::Quaterniond(R).normalized();
          sim.s = num / den;
          sim.t = md - sim.s * (sim.q * ms);
          attitude_json["used"] = true;
          attitude_json["correction_deg"] = w.norm() * 180 / M_PI;
        }
      } else {
        spdlog::warn("georef: telemetry attitude disagrees with the positions ({:.2f}°, χ² {:.1f}); not used",
                     w_att.norm() * 180 / M_PI, chi2);
      }
    }
  }

  rec.Transform(sim);
  const fs::path geo_dir = ws / "geo";
  core::EnsureDirectory(geo_dir);
  io::WriteColmapText(rec, geo_dir / "sparse_enu");

  nlohmann::json j;
  j["version"] = 1;
  j["origin"] = {{"lat", origin.lat}, {"lon", origin.lon}, {"alt", origin.alt}};
  j["origin_source"] = o.origin ? "option" : "telemetry centroid";
  j["vertical_datum"] = use_hae ? "WGS84 ellipsoid" : "MSL";
  j["frame"] = "local East-North-Up (topocentric) metres at origin: x east, y north, z up";
  j["similarity"] = SimJson(sim);
  j["rotation_about_track_from"] = roll_source;
  j["attitude"] = attitude_json;
  std::vector<double> res;
  nlohmann::json per = nlohmann::json::array();
  size_t n_in = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const Eigen::Vector3d d = sim.Apply(src[i]) - dst[i];
    per.push_back({{"name", pairs[i].name}, {"residual_m", d.norm()}, {"enu_error", {d.x(), d.y(), d.z()}},
                   {"inlier", static_cast<bool>(inliers[i])}});
    if (inliers[i]) res.push_back(d.norm()), ++n_in;
  }
  double sq = 0;
  for (double r : res) sq += r * r;
  j["residuals"] = {{"rms_m", std::sqrt(sq / std::max<size_t>(1, res.size()))},
                    {"median_m", Median(res)},
                    {"max_m", res.empty() ? 0.0 : *std::max_element(res.begin(), res.end())},
                    {"sigma_per_axis_m", sigma},
                    {"per_image", per}};
  j["cameras"] = pairs.size();
  j["inliers"] = n_in;
  // Expected 3D error of the frame's position from N independent noisy positions (σ per axis).
  j["expected_translation_error_m"] = sigma * std::sqrt(3.0 / static_cast<double>(std::max<size_t>(1, n_in)));
  const UtmZone zone = frame.utm_zone();
  j["utm"] = {{"zone", zone.zone}, {"north", zone.north}, {"epsg", zone.Epsg()}, {"name", zone.Name()}};
  j["proj"] = {{"enu_from_wgs84", frame.EnuPipeline()}, {"utm_from_wgs84", frame.UtmPipeline()},
               {"wgs84_crs", "EPSG:4979"}};
  j["to_wgs84"] = "WGS84 (lon, lat, h) = inverse of proj.enu_from_wgs84 applied to X_enu";
  j["wkt_utm"] = UtmWkt(zone);
  core::WriteJson(geo_dir / "georef.json", j);
  spdlog::info("georef: {} of {} cameras inliers, residual RMS {:.2f} m, scale {:.4f} → {}", n_in, pairs.size(),
               j["residuals"]["rms_m"].get<double>(), sim.s, (geo_dir / "georef.json").string());
  return j;
}

}  // namespace fmv3d::geo
