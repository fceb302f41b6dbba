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
#include <tuple>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/telemetry.h"
#include "fmv3d/geo/accuracy.h"
#include "fmv3d/geo/frame_centres.h"
#include "fmv3d/geo/trajectory.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

void GeorefOptions::Check() const {
  if (min_cameras < 3) throw Error("georef: at least 3 cameras are needed");
  if (max_samples < 1) throw Error("georef: max_samples must be positive");
  if (!(min_inlier_threshold > 0)) throw Error("georef: min_inlier_threshold must be positive");
  if (origin && !(std::abs(origin->lat) <= 90 && std::abs(origin->lon) <= 180 && std::isfinite(origin->alt)))
    throw Error(fmt::format("georef: bad origin {}, {}, {}", origin->lat, origin->lon, origin->alt));
  if (!(min_fit_fraction >= 0 && min_fit_fraction <= 1)) throw Error("georef: min_fit_fraction must be in [0, 1]");
  if (!(prior_sigma_m > 0)) throw Error("georef: --prior-sigma must be positive");
  if (!(attitude_sigma_deg > 0)) throw Error("georef: attitude_sigma_deg must be positive");
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

// Unit normal of the ground plane of the sparse points, pointing towards `above`: the plane with the most points
// within 1% of the points' spread (deterministic RANSAC over 3-point samples), refitted to those points by their
// smallest principal axis. A plain fit to every point is tilted by walls and roofs (a synthetic pass by a
// building: +5 m of DSM bias).
std::optional<Eigen::Vector3d> GroundNormal(const core::Reconstruction& rec, const Eigen::Vector3d& above) {
  if (rec.points.size() < 10) return std::nullopt;
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(rec.points.size());
  for (const auto& [id, p] : rec.points) pts.push_back(p.xyz);
  auto fit = [](const std::vector<Eigen::Vector3d>& v) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : v) mean += p;
    mean /= static_cast<double>(v.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : v) cov += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    return std::make_pair(Eigen::Vector3d(eig.eigenvectors().col(0)), mean);
  };
  auto [normal, centre] = fit(pts);
  std::vector<double> dist(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) dist[i] = (pts[i] - centre).norm();
  const double threshold = 0.01 * Median(dist);
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  size_t best = 0;
  for (int it = 0; it < 500; ++it) {
    const Eigen::Vector3d a = pts[pick(rng)], b = pts[pick(rng)], c = pts[pick(rng)];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-12) continue;
    n.normalize();
    size_t count = 0;
    for (const auto& p : pts) count += std::abs(n.dot(p - a)) <= threshold;
    if (count > best) best = count, normal = n, centre = a;
  }
  std::vector<Eigen::Vector3d> inliers;
  for (const auto& p : pts)
    if (std::abs(normal.dot(p - centre)) <= threshold) inliers.push_back(p);
  if (inliers.size() >= 10) std::tie(normal, centre) = fit(inliers);
  if (normal.dot(above - centre) < 0) normal = -normal;
  return normal;
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

// Telemetry camera-to-ENU rotation of a sample with the full ST 0601 angle chain, else nullopt.
std::optional<Eigen::Matrix3d> TelemetryAttitude(const telemetry::TelemetrySample& t) {
  if (!t.platform_heading || !t.platform_pitch || !t.platform_roll || !t.sensor_relative_azimuth ||
      !t.sensor_relative_elevation || !t.sensor_relative_roll)
    return std::nullopt;
  telemetry::St0601Attitude a;
  a.platform_heading = *t.platform_heading;
  a.platform_pitch = *t.platform_pitch;
  a.platform_roll = *t.platform_roll;
  a.sensor_relative_azimuth = *t.sensor_relative_azimuth;
  a.sensor_relative_elevation = *t.sensor_relative_elevation;
  a.sensor_relative_roll = *t.sensor_relative_roll;
  return telemetry::CameraToEnuFromSt0601(a);
}

bool HasPosition(const telemetry::TelemetrySample& s) {
  return s.sensor_latitude && s.sensor_longitude && (s.sensor_altitude_hae || s.sensor_altitude_msl);
}

// One (model camera, telemetry) correspondence: a keyframe (named) or a telemetry packet paired with the
// model trajectory at its time (unnamed).
struct Pair {
  std::string name;
  Eigen::Vector3d centre;        // model camera centre
  Eigen::Quaterniond rotation;   // model world-to-camera
  GeoPoint pos;                  // alt set once the vertical datum is chosen
  std::optional<double> hae, msl;
  std::optional<Eigen::Matrix3d> attitude;  // telemetry camera-to-ENU
  std::optional<GeoPoint> frame_centre;     // latitude, longitude (alt set once the vertical datum is chosen)
  std::optional<double> frame_centre_hae, frame_centre_msl;
  std::optional<double> slant_range;
  double time = 0;
  int track = -1;  // video of a packet pair; -1 for keyframes
};

Pair MakePair(const std::string& name, const Eigen::Vector3d& centre, const Eigen::Quaterniond& rotation,
              const telemetry::TelemetrySample& s) {
  Pair p;
  p.name = name;
  p.centre = centre;
  p.rotation = rotation;
  p.pos.lat = *s.sensor_latitude;
  p.pos.lon = *s.sensor_longitude;
  p.hae = s.sensor_altitude_hae;
  p.msl = s.sensor_altitude_msl;
  p.attitude = TelemetryAttitude(s);
  if (s.frame_center_latitude && s.frame_center_longitude)
    p.frame_centre = GeoPoint{*s.frame_center_latitude, *s.frame_center_longitude, 0};
  p.frame_centre_hae = s.frame_center_hae;
  p.frame_centre_msl = s.frame_center_elevation;
  p.slant_range = s.slant_range;
  p.time = s.time;
  return p;
}

// Lag-1 autocorrelation of consecutive residual vectors along each track: GPS errors that persist over
// several packets (a receiver updating slower than the video, multipath) count as fewer independent samples.
double ResidualAutocorrelation(const std::vector<Pair>& pairs, const std::vector<Eigen::Vector3d>& residual,
                               const std::vector<char>& inliers) {
  double num = 0, den = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!inliers[i]) continue;
    den += residual[i].squaredNorm();
    if (i + 1 < pairs.size() && inliers[i + 1] && pairs[i + 1].track == pairs[i].track)
      num += residual[i].dot(residual[i + 1]);
  }
  return den > 0 ? std::clamp(num / den, 0.0, 0.999) : 0.0;
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
    g.consistent_with_telemetry = j.value("consistent_with_telemetry", true);
    if (j.contains("expected_accuracy")) g.accuracy = GeorefAccuracy::FromJson(j["expected_accuracy"]);
    return g;
  } catch (const std::exception& e) {
    throw Error(p.string() + ": malformed georef (" + e.what() + ") — run `fmv3d georef` again");
  }
}

namespace {

// Drops observations whose reprojection error exceeds max_px, then points left with fewer than two.
size_t DropBadObservations(core::Reconstruction* rec, double max_px) {
  size_t removed = 0;
  for (auto it = rec->points.begin(); it != rec->points.end();) {
    auto& p = it->second;
    std::vector<core::TrackElement> kept;
    for (const auto& el : p.track) {
      if (sfm::ObservationError(*rec, el.image_id, el.point2d_idx, p.xyz) <= max_px) {
        kept.push_back(el);
      } else {
        rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
        ++removed;
      }
    }
    p.track = std::move(kept);
    if (p.track.size() < 2) {
      for (const auto& el : p.track) rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
      it = rec->points.erase(it);
    } else {
      ++it;
    }
  }
  return removed;
}

// Camera-to-ENU rotation of a keyframe from its telemetry: the full ST 0601 angle chain when present, else the
// line of sight from the sensor to the frame centre (EG0104), with no roll about it (image rows level); and the
// ground height under the frame centre. nullopt when the telemetry has neither.
struct TelemetryView {
  Eigen::Matrix3d camera_to_enu;
  std::optional<double> ground_z;
};
std::optional<TelemetryView> ViewFromTelemetry(const Pair& p, const LocalFrame& frame) {
  const Eigen::Vector3d c = frame.ToEnu(p.pos);
  std::optional<double> ground_z;
  std::optional<Eigen::Vector3d> target;
  if (p.frame_centre && p.slant_range && *p.slant_range > 0) {
    GeoPoint fc = *p.frame_centre;
    fc.alt = p.pos.alt;  // horizontal position only: the height follows from the slant range
    const Eigen::Vector3d f = frame.ToEnu(fc);
    const double horizontal = (f - c).head<2>().norm();
    if (horizontal < *p.slant_range) {
      const double drop = std::sqrt(*p.slant_range * *p.slant_range - horizontal * horizontal);
      target = Eigen::Vector3d(f.x(), f.y(), c.z() - drop);
      ground_z = c.z() - drop;
    }
  }
  if (p.attitude) return TelemetryView{*p.attitude, ground_z};
  if (!target) return std::nullopt;
  const Eigen::Vector3d d = (*target - c).normalized();
  const Eigen::Vector3d x = d.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-6) return std::nullopt;  // looking straight down: the roll is undefined
  TelemetryView v;
  v.camera_to_enu.col(0) = x.normalized();
  v.camera_to_enu.col(2) = d;
  v.camera_to_enu.col(1) = d.cross(v.camera_to_enu.col(0));
  v.ground_z = ground_z;
  return v;
}

// RMS reprojection error (pixels) of a model's observations, recomputed (a points3D.txt error may be absent).
double ReprojectionRms(const core::Reconstruction& rec) {
  double sq = 0;
  size_t n = 0;
  for (const auto& [id, img] : rec.images) {
    const core::Camera& cam = rec.cameras.at(img.camera_id);
    for (size_t k = 0; k < img.points2d.size(); ++k) {
      const auto pit = rec.points.find(static_cast<uint64_t>(img.point3d_ids[k]));
      if (img.point3d_ids[k] == core::kNoPoint3D || pit == rec.points.end()) continue;
      const Eigen::Vector3d xc = img.pose.Transform(pit->second.xyz);
      if (xc.z() <= 0) continue;
      sq += (cam.Project(xc) - img.points2d[k]).squaredNorm();
      ++n;
    }
  }
  return n ? std::sqrt(sq / n) : 0.0;
}

// The telemetry-initialised model (see GeorefOptions::constrain): cameras at the telemetry positions and
// attitudes (ENU of `frame`), the telemetry focal, the image model's tracks with every point started on the
// ground plane under the frame centres, then bundle adjustments with the positions as priors (σ prior_sigma_m)
// and the intrinsics held: first with a plain loss (the telemetry's pointing error is common to a frame's
// points), then robust. Throws fmv3d::Error when too few keyframes carry an attitude or frame centre.
core::Reconstruction TelemetryInitialisedModel(
    const io::FramesIndex& index, core::Reconstruction rec, const std::vector<Pair>& keyframe_pairs,
    const std::map<std::string, std::pair<Eigen::Vector3d, double>>& frame_centres, const LocalFrame& frame,
    const GeorefOptions& o, nlohmann::json* info) {
  std::map<uint32_t, Eigen::Vector3d> centres, axes;
  std::vector<double> ground;
  for (const auto& p : keyframe_pairs) {
    const core::Image* img = rec.FindImageByName(p.name);
    if (!img) continue;
    const auto v = ViewFromTelemetry(p, frame);
    if (!v) continue;
    const Eigen::Vector3d c = frame.ToEnu(p.pos);
    auto& pose = rec.images.at(img->id).pose;
    pose.q = Eigen::Quaterniond(v->camera_to_enu.transpose()).normalized();
    pose.t = -(pose.q * c);
    centres[img->id] = c;
    axes[img->id] = v->camera_to_enu.col(2);
    if (v->ground_z) ground.push_back(*v->ground_z);
  }
  if (centres.size() < 3)
    throw Error(fmt::format("georef: only {} keyframes have a telemetry attitude or frame centre (3 needed)",
                            centres.size()));
  // Frames without telemetry leave the model.
  std::vector<uint32_t> drop;
  for (const auto& [id, im] : rec.images)
    if (!centres.count(id)) drop.push_back(id);
  for (uint32_t id : drop) {
    for (int64_t pid : rec.images.at(id).point3d_ids) {
      if (pid == core::kNoPoint3D) continue;
      auto& track = rec.points.at(static_cast<uint64_t>(pid)).track;
      track.erase(std::remove_if(track.begin(), track.end(), [id](const core::TrackElement& e) { return e.image_id == id; }),
                  track.end());
    }
    rec.images.erase(id);
  }
  nlohmann::json focal = nlohmann::json::array();
  for (const auto& cp : index.cameras) {
    const auto it = rec.cameras.find(cp.camera.id);
    if (it == rec.cameras.end() || cp.prior_source != "telemetry-hfov") continue;
    focal.push_back({{"camera", cp.camera.id}, {"f_image_model", it->second.f}, {"f", cp.camera.f},
                     {"k1_image_model", it->second.k1}, {"k2_image_model", it->second.k2}});
    // The whole prior camera: the image model's distortion was fitted along with its degenerate shape (a
    // synthetic telephoto pass: k2 −1.84 on a lens without distortion).
    const uint32_t id = it->second.id;
    it->second = cp.camera;
    it->second.id = id;
  }
  // Every point starts where its middle observation's ray meets the ground plane under the frame centres (a
  // telephoto clip's rays are too close to parallel to triangulate before the attitudes are refined); without
  // frame centres and slant ranges, it is triangulated from the telemetry cameras.
  const std::optional<double> ground_z = ground.empty() ? std::nullopt : std::optional<double>(Median(ground));
  for (auto it = rec.points.begin(); it != rec.points.end();) {
    auto& p = it->second;
    bool placed = false;
    if (p.track.size() >= 2 && ground_z) {
      const auto& el = p.track[p.track.size() / 2];
      const auto& im = rec.images.at(el.image_id);
      const Eigen::Vector3d ray =
          im.pose.q.conjugate() * rec.cameras.at(im.camera_id).Unproject(im.points2d[el.point2d_idx]);
      const Eigen::Vector3d c = im.pose.Centre();
      if (ray.z() < -1e-9) {
        p.xyz = c + (*ground_z - c.z()) / ray.z() * ray;
        placed = true;
      }
    } else if (p.track.size() >= 2) {
      std::vector<core::Pose> poses;
      std::vector<Eigen::Vector2d> rays;
      for (const auto& el : p.track) {
        const auto& im = rec.images.at(el.image_id);
        poses.push_back(im.pose);
        rays.push_back(rec.cameras.at(im.camera_id).Unproject(im.points2d[el.point2d_idx]).head<2>());
      }
      Eigen::Vector3d X;
      placed = geometry::TriangulateDLT(poses, rays, &X);
      for (const auto& pose : poses) placed = placed && geometry::HasPositiveDepth(pose, X);
      if (placed) p.xyz = X;
    }
    if (!placed) {
      for (const auto& el : p.track) rec.images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
      it = rec.points.erase(it);
    } else {
      ++it;
    }
  }
  sfm::BundleAdjustmentConfig config;
  config.centre_priors = centres;
  config.centre_prior_sigma = o.prior_sigma_m;
  config.centre_prior_huber = 1e6;
  // The optical axes hold the rotation about the flight line, which straight-line positions leave free.
  config.axis_priors = axes;
  config.axis_prior_sigma_rad = o.attitude_sigma_deg * M_PI / 180;
  for (const auto& [id, cam] : rec.cameras) config.constant_cameras.insert(id);
  sfm::BundleAdjustmentOptions ba;
  ba.max_iterations = 200;
  ba.loss = sfm::BundleAdjustmentOptions::Loss::kTrivial;
  ba.refine_k1 = ba.refine_k2 = false;
  sfm::UpdatePointErrors(&rec);
  const double start_px = rec.MeanReprojectionError();
  const auto plain = sfm::BundleAdjust(&rec, config, ba);
  size_t dropped = DropBadObservations(&rec, 10.0);
  ba.loss = sfm::BundleAdjustmentOptions::Loss::kCauchy;
  ba.loss_scale_px = 1.0;
  sfm::BundleAdjust(&rec, config, ba);
  dropped += DropBadObservations(&rec, 4.0);
  auto last = sfm::BundleAdjust(&rec, config, ba);
  if (!plain.success || !last.success) throw Error("georef: the bundle adjustment of the telemetry model failed");
  // Frame centres at their slant range as priors (the point along each optical axis), weighed by their own
  // scatter about the adjusted model, which they then tighten: estimated again after each adjustment until it
  // settles (a variance-component estimate; a platform's own, metres-off frame centres end with little weight).
  nlohmann::json sight_sigmas = nlohmann::json::array();
  for (const auto& [id, img] : rec.images) {
    const auto it = frame_centres.find(img.name);
    if (it != frame_centres.end()) config.sight_priors[id] = it->second;
  }
  for (int round = 0; config.sight_priors.size() >= 3 && round < 5; ++round) {
    std::vector<double> norms;
    for (const auto& [id, fr] : config.sight_priors) {
      const core::Pose& pose = rec.images.at(id).pose;
      norms.push_back((pose.Centre() + fr.second * (pose.q.conjugate() * Eigen::Vector3d::UnitZ()) - fr.first).norm());
    }
    const double sigma_fc = std::max(0.005, Median(norms) / 1.538);  // per axis, from the 3D median (χ₃)
    sight_sigmas.push_back(sigma_fc);
    if (round > 0 && sigma_fc > 0.8 * config.sight_prior_sigma) break;  // settled
    config.sight_prior_sigma = sigma_fc;
    const auto r = sfm::BundleAdjust(&rec, config, ba);
    if (!r.success) break;
    last = r;
  }
  if (config.sight_priors.size() < 3) config.sight_priors.clear();
  sfm::UpdatePointErrors(&rec);
  double prior_sq = 0;
  for (const auto& [id, c] : centres) prior_sq += (rec.images.at(id).pose.Centre() - c).squaredNorm();
  *info = {{"keyframes", centres.size()},
           {"frames_left_out", drop.size()},
           {"ground_z_start_m", ground_z ? nlohmann::json(*ground_z) : nlohmann::json()},
           {"focal_from_telemetry", focal},
           {"prior_sigma_m", o.prior_sigma_m},
           {"attitude_sigma_deg", o.attitude_sigma_deg},
           {"mean_reprojection_px_start", start_px},
           {"reprojection_rms_px", last.final_rms_px},
           {"points", rec.points.size()},
           {"observations_dropped", dropped},
           {"frame_centre_priors", config.sight_priors.size()},
           {"frame_centre_prior_sigma_m", sight_sigmas},
           {"centre_rms_from_telemetry_m", std::sqrt(prior_sq / centres.size())}};
  spdlog::info("georef: telemetry-initialised model: {} keyframes, {} points, reprojection {:.2f} → {:.3f} px RMS, "
               "centres {:.2f} m RMS from the telemetry",
               centres.size(), rec.points.size(), start_px, last.final_rms_px, std::sqrt(prior_sq / centres.size()));
  return rec;
}

}  // namespace

nlohmann::json RunGeorefStage(const fs::path& ws, const GeorefOptions& o) {
  o.Check();
  const fs::path frames_json = ws / "frames" / "frames.json", sparse = ws / "sparse";
  if (!fs::exists(frames_json)) throw Error(ws.string() + ": no frames/frames.json — run `fmv3d frames` first");
  if (!fs::exists(sparse / "images.txt")) throw Error(ws.string() + ": no sparse/ model — run `fmv3d sparse` first");
  const io::FramesIndex index = io::ReadFramesIndex(frames_json);
  core::Reconstruction rec = io::ReadColmapText(sparse);

  // Pairs (model camera, telemetry): the registered keyframes' own telemetry, and — when frames/telemetry.json
  // holds the videos' whole tracks — every packet paired with the model trajectory at its time.
  std::vector<Pair> keyframe_pairs, track_pairs;
  size_t with_telemetry = 0;
  std::map<std::string, std::vector<TrajectoryKnot>> knots_by_source;
  for (const auto& f : index.frames) {
    const core::Image* img = rec.FindImageByName(f.name);
    if (img) knots_by_source[f.source].push_back({f.timestamp, img->pose.Centre(), img->pose.q});
    if (!f.telemetry.is_object()) continue;
    nlohmann::json t = f.telemetry;
    if (!t.contains("time")) t["time"] = f.timestamp;
    telemetry::TelemetrySample s;
    try {
      s = telemetry::TelemetryFromJson(t);
    } catch (const Error& e) {
      throw Error(frames_json.string() + ": frame " + f.name + ": " + e.what());
    }
    if (!HasPosition(s)) continue;
    ++with_telemetry;
    if (!img) continue;
    keyframe_pairs.push_back(MakePair(f.name, img->pose.Centre(), img->pose.q, s));
  }
  if (with_telemetry == 0)
    throw Error(frames_json.string() + ": no frame carries a telemetry position (georef needs KLV, DJI SRT or GPS)");
  if (static_cast<int>(keyframe_pairs.size()) < o.min_cameras)
    throw Error(fmt::format("georef: only {} registered frames have telemetry positions ({} needed)",
                            keyframe_pairs.size(), o.min_cameras));
  nlohmann::json track_json = {{"used", false}};
  const fs::path tracks_path = ws / "frames" / "telemetry.json";
  if (o.use_track && fs::exists(tracks_path)) {
    size_t spanned = 0, samples = 0;
    for (const auto& track : telemetry::ReadTelemetryTracks(tracks_path)) {
      const auto it = knots_by_source.find(track.source);
      if (it == knots_by_source.end() || it->second.size() < 2) continue;
      const CameraTrajectory traj(it->second);
      for (const auto& s : track.samples) {
        if (!HasPosition(s)) continue;
        ++samples;
        const auto k = traj.At(s.time);
        if (!k) continue;
        ++spanned;
        track_pairs.push_back(MakePair("", k->centre, k->rotation, s));
        track_pairs.back().time = s.time;
        track_pairs.back().track = static_cast<int>(std::distance(knots_by_source.begin(), it));
      }
    }
    track_json = {{"samples", samples}, {"inside_registered_span", spanned}, {"used", false}};
    if (track_pairs.size() <= keyframe_pairs.size()) track_pairs.clear();  // nothing gained over the keyframes
  }
  const bool use_track = !track_pairs.empty();
  std::vector<Pair>& pairs = use_track ? track_pairs : keyframe_pairs;
  if (use_track) track_json["used"] = true;
  // One vertical datum for every pair: ellipsoidal heights when every used sample states them, else MSL.
  const bool use_hae = std::all_of(pairs.begin(), pairs.end(), [](const Pair& p) { return p.hae.has_value(); });
  for (auto* set : {&keyframe_pairs, &track_pairs})
    for (auto& p : *set) p.pos.alt = use_hae && p.hae ? *p.hae : (p.msl ? *p.msl : *p.hae);

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

  nlohmann::json attitude_json = {{"used", false}};
  std::vector<Eigen::Matrix3d> rel;  // telemetry model-to-ENU rotations, for the joint refinement when used
  std::vector<size_t> rel_pair;      // their pairs
  double attitude_sigma = 0, attitude_n_eff = 0;
  if (roll_source == "camera positions") {
    for (size_t i = 0; i < pairs.size(); ++i) {
      if (!inliers[i]) continue;
      if (!pairs[i].attitude) continue;
      // camera-to-ENU · model-to-camera = model-to-ENU rotation
      rel.push_back(*pairs[i].attitude * pairs[i].rotation.toRotationMatrix());
      rel_pair.push_back(i);
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
      std::vector<Eigen::Vector3d> att_res(pairs.size(), Eigen::Vector3d::Zero());
      std::vector<char> att_in(pairs.size(), 0);
      for (size_t k = 0; k < rel.size(); ++k) {
        att_res[rel_pair[k]] = LogRotation(rel[k] * r_att.transpose());
        att_in[rel_pair[k]] = 1;
        sq += att_res[rel_pair[k]].squaredNorm();
      }
      const double sigma_att = std::max(1e-4, std::sqrt(sq / (3.0 * rel.size())));  // rad per axis
      attitude_sigma = sigma_att;
      // Between keyframes the model's rotation is interpolated and misses the camera's jitter, an error shared
      // by neighbouring packets: they count as fewer samples.
      const double rho_att = ResidualAutocorrelation(pairs, att_res, att_in);
      attitude_n_eff = std::max(1.0, rel.size() * (1 - rho_att) / (1 + rho_att));
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
                       {"residual_autocorrelation", rho_att},
                       {"effective_samples", attitude_n_eff},
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
    if (!attitude_json["used"].get<bool>()) rel.clear();
  }

  // Frame centres at their slant range (geo/frame_centres.h): a second measurement of the sensor positions,
  // fused into the scale and translation when it agrees with the GPS.
  nlohmann::json frame_centres_json = {{"used", false}, {"observations", 0}};
  std::optional<double> fused_translation_error;
  std::optional<ScaleShift> fused_frame_centres;  // when used: for the accuracy, with their points and σ
  std::vector<Eigen::Vector3d> frame_centre_points;
  double frame_centre_sigma = 0;
  std::map<std::string, std::pair<Eigen::Vector3d, double>> frame_centre_by_name;  // keyframes': ENU, slant range
  if (o.use_frame_centres) {
    // The geoid undulation from the packets that state both heights converts a frame centre's other datum. A
    // mean, not a median: both heights are 2-byte codes of one altitude, so their difference takes just two values
    // around N (the median would pick one, up to half a step off); the GPS noise spreads the altitudes over many
    // steps and the mean of the two values is N. (Trimmed to ±1 m of the median against outliers.)
    std::vector<double> undulations;
    for (const auto& p : pairs)
      if (p.hae && p.msl) undulations.push_back(*p.hae - *p.msl);
    std::optional<double> undulation;
    double undulation_sigma = 0;  // of the mean
    if (!undulations.empty()) {
      const double med = Median(undulations);
      double sum = 0, sq = 0;
      size_t n = 0;
      for (double u : undulations)
        if (std::abs(u - med) <= 1.0) sum += u, sq += u * u, ++n;
      undulation = sum / static_cast<double>(n);
      undulation_sigma = std::sqrt(std::max(0.0, sq / n - *undulation * *undulation) / static_cast<double>(n));
    }
    // A frame centre's height in the fit's datum. Its elevation is encoded in 2 bytes over 19.9 km (ST 0601
    // tags 25 MSL and 78 HAE): 0.30 m steps, so each code is an interval one step wide. When a packet states both,
    // the truth lies in both: the other datum's code, moved by the undulation, narrows the interval wherever the
    // two grids do not line up — its edges blurred by the undulation estimate's σ.
    const double step = 19900.0 / 65535;
    const auto on_grid = [&](double h) {
      const double k = (h + 900) / step;
      return std::abs(k - std::round(k)) < 1e-4;
    };
    struct Height {
      double value = 0;
      bool coded = false;             // a 2-byte code: the truth is within ±step/2 of value
      std::optional<double> other;    // the other datum's code, moved into this one (when coded too)
      bool operator==(const Height& h) const {
        return std::abs(value - h.value) < 1e-6 && coded == h.coded && other.has_value() == h.other.has_value() &&
               (!other || std::abs(*other - *h.other) < 1e-6);
      }
    };
    const auto frame_centre_height = [&](const Pair& p) -> std::optional<Height> {
      const auto& same = use_hae ? p.frame_centre_hae : p.frame_centre_msl;
      const auto& other = use_hae ? p.frame_centre_msl : p.frame_centre_hae;
      const std::optional<double> moved =
          other && undulation ? std::optional<double>(*other + (use_hae ? *undulation : -*undulation)) : std::nullopt;
      if (same) {
        Height h{*same, on_grid(*same), std::nullopt};
        if (h.coded && moved && on_grid(*other) && std::abs(*moved - *same) < step + 5 * undulation_sigma)
          h.other = moved;
        return h;
      }
      if (moved) return Height{*moved, on_grid(*other), std::nullopt};
      return std::nullopt;
    };
    // Prior of the offset u (truth − value) common to frame centres that all decode alike: uniform over the step,
    // times the other code's step (blurred by the undulation's σ) when there is one.
    const auto offset_prior = [&](const Height& h) {
      std::vector<std::pair<double, double>> nodes;
      const int n = 61;
      const double s_n = std::max(undulation_sigma, 1e-4);
      for (int k = 0; k < n; ++k) {
        const double u = step * ((k + 0.5) / n - 0.5);
        double w = 1;
        if (h.other) {
          const double lo = *h.other - h.value - 0.5 * step, hi = *h.other - h.value + 0.5 * step;
          w = 0.5 * (std::erf((hi - u) / (std::sqrt(2.0) * s_n)) - std::erf((lo - u) / (std::sqrt(2.0) * s_n)));
        }
        nodes.emplace_back(u, w);
      }
      return nodes;
    };
    const auto prior_sd = [](const std::vector<std::pair<double, double>>& nodes) {
      double w = 0, m = 0, q = 0;
      for (const auto& [u, p] : nodes) w += p, m += p * u, q += p * u * u;
      return w > 0 ? std::sqrt(std::max(0.0, q / w - (m / w) * (m / w))) : 0.0;
    };
    const Eigen::Matrix3d R = sim.q.toRotationMatrix();
    std::vector<Eigen::Vector3d> s_in, d_in, res(pairs.size());
    for (size_t i = 0; i < pairs.size(); ++i) {
      res[i] = sim.Apply(src[i]) - dst[i];
      if (inliers[i]) s_in.push_back(src[i]), d_in.push_back(dst[i]);
    }
    // Only the keyframes' lines of sight: between keyframes the model's rotation is interpolated and misses the
    // gimbal's jitter, which the slant range turns into metres (0.4° at 700 m: 5 m, against 2 cm at keyframes).
    std::vector<LineOfSight> sights;
    std::vector<Height> heights;
    for (const Pair& p : keyframe_pairs) {
      const auto h = frame_centre_height(p);
      if (!p.frame_centre || !p.slant_range || !(*p.slant_range > 0) || !h) continue;
      heights.push_back(*h);
      sights.push_back({p.centre, p.rotation.conjugate() * Eigen::Vector3d::UnitZ(), *p.slant_range,
                        frame.ToEnu({p.frame_centre->lat, p.frame_centre->lon, h->value}), 0});
      frame_centre_by_name[p.name] = {sights.back().frame_centre, *p.slant_range};
    }
    const double rho_p = use_track ? ResidualAutocorrelation(pairs, res, inliers) : 0.0;
    const double n_eff_p = std::max(1.0, s_in.size() * (1 - rho_p) / (1 + rho_p));
    // The positions' scale and translation under a rotation, with their covariance (σ², effective samples).
    const auto positions_under = [&](const Eigen::Matrix3d& rotation, ScaleShift* out) {
      if (!FitScaleShift(rotation, s_in, d_in, std::vector<double>(s_in.size(), 1.0), out)) return false;
      out->covariance *= sigma * sigma * static_cast<double>(s_in.size()) / n_eff_p;
      return true;
    };
    ScaleShift positions;
    if (sights.empty())
      frame_centres_json["why"] = "no packet states a frame centre with its elevation and a slant range";
    if (!sights.empty() && positions_under(R, &positions)) {
      // Over flat ground every frame centre decodes alike and carries the same offset, which no number of
      // packets averages: the fusion takes it as a posterior over that offset (its prior above). Over relief the
      // codes differ and their errors partly average: a Gaussian floor of the prior's σ over √(distinct codes).
      // Heights that are not 2-byte codes carry no such error.
      const bool coded = !heights.empty() && std::all_of(heights.begin(), heights.end(), [](const Height& h) {
        return h.coded;
      });
      size_t steps = heights.empty() ? 0 : 1;
      for (size_t i = 1; i < heights.size(); ++i) {
        bool seen = false;
        for (size_t k = 0; k < i && !seen; ++k) seen = heights[k] == heights[i];
        steps += seen ? 0 : 1;
      }
      const bool one_step = coded && steps == 1;
      const std::vector<std::pair<double, double>> vertical_prior =
          one_step ? offset_prior(heights.front()) : std::vector<std::pair<double, double>>{};
      double floor_sd = 0;
      if (coded && !one_step) {
        for (const auto& h : heights) floor_sd += prior_sd(offset_prior(h));
        floor_sd /= static_cast<double>(heights.size()) * std::sqrt(static_cast<double>(steps));
      }
      const Eigen::Vector3d systematic(0, 0, floor_sd);
      const double interval_sd = heights.empty() || !coded ? 0.0 : prior_sd(offset_prior(heights.front()));
      FrameCentreFusion fusion = FuseFrameCentres(R, positions, sights, o.min_inlier_threshold, systematic, vertical_prior);
      if (fusion.inliers >= 3 && fusion.sigma_m > 0) {
        // Refine the rotation on positions, lines of sight and attitudes together (frame centres off the track
        // fix the roll a straight track leaves to the ground plane, and spread ones the whole rotation), each
        // weighed by its own noise (the frame centres': about a fit of their own, OwnScatter), then fuse scale
        // and translation again: kept only if the frame centres then agree with the positions.
        JointMeasurements m;
        m.src = s_in, m.dst = d_in;
        m.position_sigma = sigma * std::sqrt(s_in.size() / n_eff_p);
        m.attitudes = rel;
        m.attitude_sigma_rad = attitude_n_eff > 0 ? attitude_sigma * std::sqrt(rel.size() / attitude_n_eff) : 1.0;
        for (size_t i = 0; i < sights.size(); ++i)
          if (fusion.inlier_mask[i]) m.sights.push_back(sights[i]);
        const SightScatter own = OwnScatter(sim, m.sights, fusion.sigma_m);
        m.sight_sigma = own.sigma_effective;
        const core::Sim3 joint = RefineSimilarity(sim, m);
        const Eigen::Matrix3d R2 = joint.q.toRotationMatrix();
        ScaleShift positions2;
        if (positions_under(R2, &positions2)) {
          FrameCentreFusion again = FuseFrameCentres(R2, positions2, sights, o.min_inlier_threshold, systematic, vertical_prior);
          // The turn must also be one the positions and attitudes allow — a gross-error gate (χ², 3 dof, 99.99%):
          // frame centres whose errors are smooth along the track fit a similarity of their own too well and would
          // look precise. (Not 99.9%: the positions' rotation information ignores their errors' correlation and
          // is optimistic; a synthetic orbit's correct turn of 0.61° scored 20.8.)
          Eigen::Matrix3d info_pa = RotationInformation(d_in, m.position_sigma);
          if (!rel.empty()) info_pa += Eigen::Matrix3d::Identity() / std::pow(m.attitude_sigma_rad, 2) * rel.size();
          const Eigen::Vector3d turn = LogRotation(R2 * R.transpose());
          const double turn_chi2 = turn.dot(info_pa * turn);
          spdlog::debug("georef: frame centres' own σ {:.3f} m (effective {:.3f}, under the positions' rotation "
                        "{:.3f}); joint refinement turned the rotation {:.3f}° (χ² {:.1f}); frame centres χ² {:.1f} → {:.1f}",
                        own.sigma, own.sigma_effective,
                        fusion.sigma_m * std::sqrt(fusion.inliers / fusion.effective_samples),
                        turn.norm() * 180 / M_PI, turn_chi2, fusion.chi2, again.chi2);
          frame_centres_json["rotation_turn_deg"] = turn.norm() * 180 / M_PI;
          frame_centres_json["rotation_turn_chi2"] = turn_chi2;
          frame_centres_json["rotation_turn_applied"] = again.used && turn_chi2 <= 21.11;
          if (again.used && turn_chi2 <= 21.11) {
            sim.q = joint.q;
            fusion = again;
            frame_centre_sigma = own.sigma_effective;
          }
        }
      }
      frame_centres_json.update(fusion.ToJson());
      frame_centres_json["elevation_steps"] = steps;
      frame_centres_json["elevation_encoding"] =
          !coded ? "not on the 2-byte ST 0601 grid: no quantisation error"
                 : std::string(one_step ? "one 2-byte code for all: a common offset" : "several 2-byte codes: a Gaussian floor") +
                       (heights.front().other ? ", within the MSL and HAE codes' common interval" : ", within its step");
      frame_centres_json["elevation_offset_prior_sd_m"] = interval_sd;
      if (undulation) {
        frame_centres_json["geoid_undulation_m"] = *undulation;
        frame_centres_json["geoid_undulation_sigma_m"] = undulation_sigma;
      }
      if (fusion.used) {
        sim.s = fusion.fused.scale;
        sim.t = fusion.fused.translation;
        fused_translation_error = frame_centres_json["expected_translation_error_m"].get<double>();
        fused_frame_centres = fusion.fused;
        for (size_t i = 0; i < sights.size(); ++i)
          if (fusion.inlier_mask[i]) frame_centre_points.push_back(sights[i].frame_centre);
        if (!(frame_centre_sigma > 0))
          frame_centre_sigma = fusion.sigma_m * std::sqrt(fusion.inliers / fusion.effective_samples);
        spdlog::info("georef: {} frame centres at their slant range fused (σ {:.2f} m per axis, χ² {:.1f})",
                     fusion.inliers, fusion.sigma_m, fusion.chi2);
      } else {
        spdlog::info("georef: frame centres not used: {} (σ {:.2f} m, χ² {:.1f})", fusion.why, fusion.sigma_m,
                     fusion.chi2);
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
  j["frame_centres"] = frame_centres_json;
  // Residuals of the keyframes (the cameras later stages use); a keyframe is an inlier within the fit's bound.
  const double bound = std::max(o.min_inlier_threshold, 3.5 * sigma);
  std::vector<double> res;
  nlohmann::json per = nlohmann::json::array();
  size_t n_in = 0;
  for (const auto& p : keyframe_pairs) {
    const Eigen::Vector3d d = sim.Apply(p.centre) - frame.ToEnu(p.pos);
    const bool in = use_track ? d.norm() <= bound : true;
    per.push_back({{"name", p.name}, {"residual_m", d.norm()}, {"enu_error", {d.x(), d.y(), d.z()}}, {"inlier", in}});
    if (in) res.push_back(d.norm()), ++n_in;
  }
  if (!use_track)  // the keyframes are the fit: its own inlier mask
    for (size_t i = 0; i < per.size(); ++i) per[i]["inlier"] = static_cast<bool>(inliers[i]);
  if (!use_track) {
    res.clear();
    n_in = 0;
    for (size_t i = 0; i < per.size(); ++i)
      if (inliers[i]) res.push_back(per[i]["residual_m"].get<double>()), ++n_in;
  }
  double sq = 0;
  for (double r : res) sq += r * r;
  j["residuals"] = {{"rms_m", std::sqrt(sq / std::max<size_t>(1, res.size()))},
                    {"median_m", Median(res)},
                    {"max_m", res.empty() ? 0.0 : *std::max_element(res.begin(), res.end())},
                    {"sigma_per_axis_m", sigma},
                    {"per_image", per}};
  j["cameras"] = keyframe_pairs.size();
  j["inliers"] = n_in;
  // The fit itself: N pairs of which n inliers; their residuals' lag-1 autocorrelation ρ along the track turns
  // n into n·(1−ρ)/(1+ρ) independent samples (ρ ≈ 0 for white GPS noise, → 1 for a slow receiver repeated
  // per packet). Expected 3D error of the translation from them: σ·√(3/n_eff) (σ per axis).
  std::vector<Eigen::Vector3d> fit_res(pairs.size());
  size_t fit_in = 0;
  for (size_t i = 0; i < pairs.size(); ++i) fit_res[i] = sim.Apply(src[i]) - dst[i], fit_in += inliers[i] ? 1 : 0;
  const double rho = use_track ? ResidualAutocorrelation(pairs, fit_res, inliers) : 0.0;
  const double n_eff = std::max(1.0, static_cast<double>(fit_in) * (1 - rho) / (1 + rho));
  track_json["pairs"] = pairs.size();
  track_json["inliers"] = fit_in;
  track_json["residual_autocorrelation"] = rho;
  track_json["effective_samples"] = n_eff;
  j["fit"] = track_json;
  j["fit"]["from"] = use_track ? "every telemetry packet vs the model trajectory at its time" : "keyframes";
  j["expected_translation_error_m"] = fused_translation_error.value_or(sigma * std::sqrt(3.0 / n_eff));
  {
    // Expected accuracy (geo/accuracy.h): rotation from every measurement weighed, translation and scale from
    // the positions, or from their fusion with the frame centres (then at the frame centres' centroid).
    std::vector<Eigen::Vector3d> dst_in;
    for (size_t i = 0; i < dst.size(); ++i)
      if (inliers[i]) dst_in.push_back(dst[i]);
    const double sigma_eff = sigma * std::sqrt(static_cast<double>(fit_in) / n_eff);
    GeorefAccuracy acc;
    const Eigen::Matrix3d info_positions = RotationInformation(dst_in, sigma_eff);
    Eigen::Matrix3d info = info_positions;
    acc.from.push_back("positions");
    if (!rel.empty() && attitude_sigma > 0) {
      info += Eigen::Matrix3d::Identity() * (attitude_n_eff / (attitude_sigma * attitude_sigma));
      acc.from.push_back("attitudes");
    }
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : dst_in) centroid += p;
    centroid /= static_cast<double>(std::max<size_t>(1, dst_in.size()));
    if (fused_frame_centres && !frame_centre_points.empty()) {
      info += RotationInformation(frame_centre_points, frame_centre_sigma);
      acc.from.push_back("frame centres");
      acc.pivot = Eigen::Vector3d::Zero();
      for (const auto& p : frame_centre_points) acc.pivot += p;
      acc.pivot /= static_cast<double>(frame_centre_points.size());
      Eigen::Matrix<double, 3, 4> J;
      J.col(0) = (acc.pivot - sim.t) / sim.s;
      J.rightCols<3>().setIdentity();
      acc.position_cov = J * fused_frame_centres->covariance * J.transpose();
      acc.scale_sigma_rel = std::sqrt(std::max(0.0, fused_frame_centres->covariance(0, 0))) / sim.s;
    } else {
      acc.pivot = centroid;
      acc.position_cov = Eigen::Matrix3d::Identity() * (sigma * sigma / n_eff);
      double spread = 0;
      for (const auto& p : dst_in) spread += (p - centroid).squaredNorm();
      acc.scale_sigma_rel = spread > 0 ? sigma_eff / std::sqrt(spread) : 0.0;
    }
    // A rotation no measurement fixes (the roll about a straight track, set by the ground plane) is not known.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(info);
    const double five_deg = 5 * M_PI / 180;
    acc.rotation_known = roll_source == "camera positions" || fused_frame_centres.has_value();
    acc.rotation_known = acc.rotation_known && eig.eigenvalues().allFinite() &&
                         eig.eigenvalues().minCoeff() > 1 / (five_deg * five_deg);
    if (acc.rotation_known) acc.rotation_cov = info.inverse();
    {
      const Eigen::Vector3d sp = info_positions.inverse().diagonal().cwiseSqrt() * 180 / M_PI;
      const Eigen::Vector3d sa = info.inverse().diagonal().cwiseSqrt() * 180 / M_PI;
      spdlog::debug("georef accuracy: rotation σ (°) positions {:.3f} {:.3f} {:.3f}, attitudes {:.3f}, all {:.3f} {:.3f} {:.3f}",
                    sp.x(), sp.y(), sp.z(), attitude_n_eff > 0 ? attitude_sigma / std::sqrt(attitude_n_eff) * 180 / M_PI : -1.0,
                    sa.x(), sa.y(), sa.z());
    }
    j["expected_accuracy"] = acc.ToJson();
  }
  // A model whose trajectory has the telemetry's shape fits nearly every packet (synthetic flights: 98%); when
  // a large part does not fit, the reconstruction's shape is wrong (too little parallax, a telephoto pair's
  // ambiguous pose) and every product placed by this similarity inherits it. Say so, loudly, in the file too.
  const double fit_fraction = pairs.empty() ? 0.0 : static_cast<double>(fit_in) / pairs.size();
  j["consistent_with_telemetry"] = fit_fraction >= o.min_fit_fraction;
  j["fit_fraction"] = fit_fraction;
  // Frame centres that disagree with the model placed by the positions say the model's shape is wrong where
  // its trajectory alone cannot (a telephoto pass's image model bends its lines of sight, not its track).
  const bool shape_off = fit_fraction < o.min_fit_fraction;
  const bool sights_off = frame_centres_json.value("why", "").find("disagree") != std::string::npos;
  // A nearly straight track leaves the image model free to bend about the track (a shallow dome or a roll that
  // grows along it) while every camera stays on the line; neither the positions nor one similarity can see that.
  // Frame centres that agree can: as priors on each optical axis they fix the shape, so such a model is built
  // again with them (a straight pass: DSM 0.97% → 0.27% of the building height).
  const bool straight_with_sights = roll_source != "camera positions" && fused_frame_centres.has_value();
  if (o.constrain == GeorefOptions::Constrain::kAlways ||
      (o.constrain == GeorefOptions::Constrain::kAuto && (shape_off || sights_off || straight_with_sights))) {
    const char* trigger = o.constrain == GeorefOptions::Constrain::kAlways ? "forced (--constrain always)"
                          : shape_off  ? "the track does not fit the model"
                          : sights_off ? "the frame centres disagree with the model"
                                       : "a nearly straight track with frame centres";
    spdlog::info("georef: {:.0f}% of the telemetry fits the model's trajectory ({}); building the model again from "
                 "the telemetry's cameras",
                 100 * fit_fraction, trigger);
    nlohmann::json info;
    core::Reconstruction model;
    try {
      model = TelemetryInitialisedModel(index, rec, keyframe_pairs, frame_centre_by_name, frame, o, &info);
    } catch (const Error& e) {
      spdlog::warn("{}; keeping the image-only model", e.what());
      info = {{"applied", false}, {"why", e.what()}};
    }
    info["trigger"] = trigger;
    if (!model.images.empty()) {
      const fs::path keep = geo_dir / "sparse_image_only";
      core::EnsureDirectory(keep);
      for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
        fs::copy_file(ws / "sparse" / f, keep / f, fs::copy_options::overwrite_existing);
      io::WriteColmapText(model, ws / "sparse");
      GeorefOptions again = o;
      again.constrain = GeorefOptions::Constrain::kNever;
      again.origin = origin;
      nlohmann::json rebuilt = RunGeorefStage(ws, again);
      // Kept when forced, or when it mends what was wrong: more of the track fits it, or (when only the frame
      // centres disagreed, or shaped a straight track's model) its frame centres agree with it and the track
      // still fits.
      // A rebuild whose frame centres still disagree mends it too when it removes more of their disagreement
      // than the whole agreement band (χ² against the positions lower by more than kFrameCentreAgreementChi2)
      // and explains the images as well: a telephoto pass with 49 keyframes, image model χ² 3096 and surface
      // 11.3 m, rebuilt χ² 39 and 1.2 m. What is left there is the rebuild's own warp (0.5% short along the
      // track for the positions, not for the frame centres), which one similarity cannot serve.
      const double image_px = ReprojectionRms(rec);
      info["reprojection_rms_px_image_only"] = image_px;
      const bool explains_images = info.value("reprojection_rms_px", 1e9) <= 1.5 * image_px + 0.1;
      const double chi2_image = frame_centres_json.value("chi2_vs_positions", 0.0);
      const nlohmann::json& rebuilt_sights = rebuilt.at("frame_centres");
      const bool has_chi2 = rebuilt_sights.contains("chi2_vs_positions");
      const double chi2_rebuilt = has_chi2 ? rebuilt_sights["chi2_vs_positions"].get<double>() : 1e300;
      info["frame_centres_chi2_image_only"] = chi2_image;
      if (has_chi2) info["frame_centres_chi2"] = chi2_rebuilt;
      const bool sights_closer = sights_off && chi2_rebuilt < chi2_image - kFrameCentreAgreementChi2 && explains_images;
      bool mended = shape_off ? rebuilt.at("fit_fraction").get<double>() > fit_fraction
                              : (rebuilt_sights.value("used", false) || sights_closer) &&
                                    rebuilt.at("fit_fraction").get<double>() >= o.min_fit_fraction;
      if (straight_with_sights && !shape_off && !sights_off) {
        // That model was sound: the rebuild (telemetry focal, intrinsics held) must also explain its images about
        // as well, or a coarse HFOV is being traded for the bend.
        mended = mended && explains_images;
      }
      if (o.constrain == GeorefOptions::Constrain::kAlways || mended) {
        info["applied"] = true;
        info["fit_fraction_image_only"] = fit_fraction;
        info["image_only_model"] = keep.string();
        rebuilt["telemetry_constrained"] = info;
        core::WriteJson(geo_dir / "georef.json", rebuilt);
        return rebuilt;
      }
      spdlog::warn("georef: the telemetry-initialised model mends nothing ({:.0f}% of the track fits it, its frame "
                   "centres {} (χ² {:.1f} against the image model's {:.1f}), reprojection {:.2f} px RMS against the "
                   "image model's {:.2f}); keeping the image-only model",
                   100 * rebuilt.at("fit_fraction").get<double>(),
                   rebuilt_sights.value("used", false) ? "agree" : "do not agree either",
                   has_chi2 ? chi2_rebuilt : -1.0, chi2_image,
                   info.value("reprojection_rms_px", -1.0), image_px);
      for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
        fs::copy_file(keep / f, ws / "sparse" / f, fs::copy_options::overwrite_existing);
      fs::remove_all(keep);
      io::WriteColmapText(rec, geo_dir / "sparse_enu");  // rewritten by the attempt
      info["applied"] = false;
      info["fit_fraction_telemetry_model"] = rebuilt.at("fit_fraction");
    }
    j["telemetry_constrained"] = info;
  } else {
    j["telemetry_constrained"] = {{"applied", false}};
  }
  if (fit_fraction < o.min_fit_fraction)
    spdlog::warn("georef: only {:.0f}% of the telemetry fits the model's trajectory: the reconstruction's shape "
                 "disagrees with the flight (too little parallax?); georeferenced products are not reliable",
                 100 * fit_fraction);
  const UtmZone zone = frame.utm_zone();
  j["utm"] = {{"zone", zone.zone}, {"north", zone.north}, {"epsg", zone.Epsg()}, {"name", zone.Name()}};
  j["proj"] = {{"enu_from_wgs84", frame.EnuPipeline()}, {"utm_from_wgs84", frame.UtmPipeline()},
               {"wgs84_crs", "EPSG:4979"}};
  j["to_wgs84"] = "WGS84 (lon, lat, h) = inverse of proj.enu_from_wgs84 applied to X_enu";
  j["wkt_utm"] = UtmWkt(zone);
  core::WriteJson(geo_dir / "georef.json", j);
  spdlog::info("georef: fit on {} {} ({} inliers, σ {:.2f} m per axis, expected translation error {:.2f} m); "
               "{} of {} keyframes inliers, scale {:.4f} → {}", pairs.size(), use_track ? "telemetry packets" : "keyframes",
               fit_in, sigma, j["expected_translation_error_m"].get<double>(), n_in, keyframe_pairs.size(), sim.s,
               (geo_dir / "georef.json").string());
  return j;
}

}  // namespace fmv3d::geo
