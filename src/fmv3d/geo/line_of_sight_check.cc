#include "fmv3d/geo/line_of_sight_check.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::geo {
namespace {

constexpr double kDeg = M_PI / 180;

// The model's ground at the image centre: where the camera's ray through the principal point meets the plane
// fitted (least squares) to the model points seen near it — within a growing share of the half diagonal until
// min_points are found; the points' median depth along the ray when that plane is degenerate or nearly parallel
// to the ray. nullopt when the image sees fewer points.
std::optional<Eigen::Vector3d> GroundAtImageCentre(const core::Reconstruction& rec, const core::Image& img,
                                                   int min_points) {
  const core::Camera& cam = rec.cameras.at(img.camera_id);
  const Eigen::Vector2d centre = cam.u0 > 0 && cam.v0 > 0 ? Eigen::Vector2d(cam.u0, cam.v0)  // the optical axis
                                                          : Eigen::Vector2d(0.5 * cam.width, 0.5 * cam.height);
  const double half_diagonal = 0.5 * std::hypot(cam.width, cam.height);
  const Eigen::Vector3d c = img.pose.Centre();
  const Eigen::Vector3d ray = (img.pose.q.conjugate() * cam.Unproject(centre)).normalized();
  for (double share : {0.1, 0.2, 0.35, 0.5, 0.75, 1.0}) {
    std::vector<Eigen::Vector3d> pts;
    std::vector<double> depth;
    for (size_t k = 0; k < img.points2d.size(); ++k) {
      if (img.point3d_ids[k] == core::kNoPoint3D) continue;
      if ((img.points2d[k] - centre).norm() > share * half_diagonal) continue;
      const auto it = rec.points.find(static_cast<uint64_t>(img.point3d_ids[k]));
      if (it == rec.points.end()) continue;
      const double d = (it->second.xyz - c).dot(ray);
      if (d > 0) pts.push_back(it->second.xyz), depth.push_back(d);
    }
    if (static_cast<int>(pts.size()) < min_points) continue;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pts) mean += p;
    mean /= static_cast<double>(pts.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : pts) cov += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    const Eigen::Vector3d n = eig.eigenvectors().col(0);
    const bool planar = eig.eigenvalues()(1) > 0 && std::abs(n.dot(ray)) > 0.1;
    const double t = planar ? n.dot(mean - c) / n.dot(ray) : core::Median(depth);
    return Eigen::Vector3d(c + (t > 0 ? t : core::Median(depth)) * ray);
  }
  return std::nullopt;
}

// The frame centre's height in the fit's datum (the other datum's moved by the sensor's undulation).
std::optional<double> FrameCentreHeight(const GeorefPair& p, VerticalDatum datum, const std::optional<double>& n) {
  const bool hae = datum == VerticalDatum::kEllipsoid;
  if (hae && p.frame_centre_hae) return *p.frame_centre_hae;
  if (!hae && p.frame_centre_msl) return *p.frame_centre_msl;
  if (!n) return std::nullopt;
  if (hae && p.frame_centre_msl) return *p.frame_centre_msl + *n;
  if (!hae && p.frame_centre_hae) return *p.frame_centre_hae - *n;
  return std::nullopt;
}

// 1σ per axis of the georeferenced position of ENU point x, from the stated accuracy (translation, rotation about
// the pivot, scale).
double GeorefSigmaAt(const GeorefAccuracy& a, const Eigen::Vector3d& x) {
  const Eigen::Vector3d d = x - a.pivot;
  double var = a.position_cov.trace() + std::pow(d.norm() * a.scale_sigma_rel, 2);
  if (a.rotation_known) var += a.rotation_cov.trace() * d.squaredNorm() - d.dot(a.rotation_cov * d);
  return std::sqrt(std::max(0.0, var) / 3);
}

}  // namespace

void LineOfSightOptions::Check() const {
  if (!(pointing_sigma_deg > 0)) throw Error("line-of-sight check: the pointing σ must be positive");
  if (!(max_chi > 0)) throw Error("line-of-sight check: max_chi must be positive");
  if (min_points < 1) throw Error("line-of-sight check: min_points must be ≥ 1");
}

std::string LineOfSightCheck::Why() const {
  switch (verdict) {
    case Verdict::kNotChecked:
      return "no keyframe states a frame centre with its height and sees enough points";
    case Verdict::kAgrees:
      return fmt::format(
          "the model's ground at the image centres lies on the telemetry's lines of sight "
          "({:.2f}° median, σ {:.2f}°)",
          median_angle_deg, median_sigma_deg);
    case Verdict::kDisagrees:
      if (median_chi <= max_chi_used)
        return fmt::format(
            "the model's ground at the image centres lies {:.0f} m below the telemetry's frame centres "
            "(median over {} keyframes, {:.1f}σ): {:.0f} m {} them along the lines of sight, at {:.1f} m "
            "against their {:.1f} m ({}); the line of sight meets the ground at or before its frame centre",
            median_below_m, keyframes.size(), median_height_chi, std::abs(median_beyond_m),
            median_beyond_m >= 0 ? "beyond" : "short of", median_ground_height_m, median_frame_centre_height_m,
            datum_name);
      return fmt::format(
          "the model's ground at the image centres is {:.2f}° (median over {} keyframes) off the "
          "telemetry's lines of sight, {:.1f}σ of the stated accuracy ({:.2f}°): on the ground "
          "{:.0f} m {} and {:.0f} m across the telemetry's frame centre, at {:.1f} m against the "
          "frame centre's {:.1f} m ({})",
          median_angle_deg, keyframes.size(), median_chi, median_sigma_deg, std::abs(median_along_m),
          median_along_m >= 0 ? "beyond" : "short of", median_across_m, median_ground_height_m,
          median_frame_centre_height_m, datum_name);
  }
  return "";
}

nlohmann::json LineOfSightCheck::ToJson() const {
  const char* v = verdict == Verdict::kAgrees ? "agrees" : verdict == Verdict::kDisagrees ? "disagrees" : "not checked";
  nlohmann::json j = {{"verdict", v}, {"why", Why()}, {"keyframes", keyframes.size()}};
  if (verdict == Verdict::kNotChecked) return j;
  j["median_angle_deg"] = median_angle_deg;
  j["median_sigma_deg"] = median_sigma_deg;
  j["median_chi"] = median_chi;
  j["median_below_frame_centre_m"] = median_below_m;
  j["median_beyond_frame_centre_m"] = median_beyond_m;
  j["median_height_chi"] = median_height_chi;
  j["median_along_m"] = median_along_m;
  j["median_across_m"] = median_across_m;
  j["median_ground_height_m"] = median_ground_height_m;
  j["median_frame_centre_height_m"] = median_frame_centre_height_m;
  nlohmann::json per = nlohmann::json::array();
  for (const auto& k : keyframes)
    per.push_back({{"name", k.name},
                   {"angle_deg", k.angle_rad / kDeg},
                   {"sigma_deg", k.sigma_rad / kDeg},
                   {"along_m", k.along_m},
                   {"across_m", k.across_m},
                   {"below_frame_centre_m", k.below_m},
                   {"beyond_frame_centre_m", k.beyond_m},
                   {"model_ground_enu", {k.model_ground.x(), k.model_ground.y(), k.model_ground.z()}},
                   {"frame_centre_enu", {k.frame_centre.x(), k.frame_centre.y(), k.frame_centre.z()}}});
  j["per_keyframe"] = per;
  return j;
}

LineOfSightCheck CheckLinesOfSight(const core::Reconstruction& model, const std::vector<GeorefPair>& keyframes,
                                   VerticalDatum datum, const LocalFrame& frame, const GeorefAccuracy* accuracy,
                                   const LineOfSightOptions& o) {
  o.Check();
  std::vector<double> undulations;
  for (const auto& p : keyframes)
    if (p.hae && p.msl) undulations.push_back(*p.hae - *p.msl);
  const std::optional<double> n = undulations.empty() ? std::nullopt : std::optional<double>(core::Median(undulations));
  LineOfSightCheck out;
  std::vector<double> angle, sigma, chi, along, across, ground_h, fc_h, below, height_chi, beyond;
  for (const auto& p : keyframes) {
    const core::Image* img = model.FindImageByName(p.name);
    auto h = FrameCentreHeight(p, datum, n);
    if (!h) h = FrameCentreHeightFromRange(p, frame);
    if (!img || !p.frame_centre || !h) continue;
    const auto g = GroundAtImageCentre(model, *img, o.min_points);
    if (!g) continue;
    SightComparison c;
    c.name = p.name;
    c.sensor = frame.ToEnu(p.pos);
    c.frame_centre = frame.ToEnu({p.frame_centre->lat, p.frame_centre->lon, *h});
    c.model_ground = *g;
    const Eigen::Vector3d sight = c.frame_centre - c.sensor, to_ground = c.model_ground - c.sensor;
    if (!(sight.norm() > 0) || !(to_ground.norm() > 0)) continue;
    c.angle_rad = std::atan2(sight.cross(to_ground).norm(), sight.dot(to_ground));
    const double geo = accuracy ? GeorefSigmaAt(*accuracy, c.model_ground) / to_ground.norm() : 0.0;
    c.sigma_rad = std::hypot(o.pointing_sigma_deg * kDeg, geo);
    // On the ground: the ray's point at G's height (when the ray descends), horizontal offsets from it.
    Eigen::Vector3d on_ray = c.frame_centre;
    if (sight.z() < -1e-9) on_ray = c.sensor + (c.model_ground.z() - c.sensor.z()) / sight.z() * sight;
    const Eigen::Vector2d u =
        sight.head<2>().norm() > 0 ? Eigen::Vector2d(sight.head<2>().normalized()) : Eigen::Vector2d::UnitY();
    const Eigen::Vector2d d = (c.model_ground - on_ray).head<2>();
    c.along_m = d.dot(u);
    c.across_m = d.x() * u.y() - d.y() * u.x();
    c.below_m = std::max(0.0, c.frame_centre.z() - c.model_ground.z());
    c.beyond_m = to_ground.dot(sight.normalized()) - sight.norm();
    const double geo_m = accuracy ? GeorefSigmaAt(*accuracy, c.model_ground) : 0.0;
    c.height_sigma_m = std::hypot(geo_m, sight.norm() * o.pointing_sigma_deg * kDeg);
    below.push_back(c.below_m), height_chi.push_back(c.below_m / c.height_sigma_m), beyond.push_back(c.beyond_m);
    angle.push_back(c.angle_rad / kDeg), sigma.push_back(c.sigma_rad / kDeg), chi.push_back(c.angle_rad / c.sigma_rad);
    along.push_back(c.along_m), across.push_back(c.across_m);
    ground_h.push_back(frame.ToGeodetic(c.model_ground).alt), fc_h.push_back(frame.ToGeodetic(c.frame_centre).alt);
    out.keyframes.push_back(c);
  }
  if (out.keyframes.empty()) return out;
  out.median_angle_deg = core::Median(angle);
  out.median_sigma_deg = core::Median(sigma);
  out.median_chi = core::Median(chi);
  out.median_along_m = core::Median(along);
  out.median_across_m = core::Median(across);
  out.median_ground_height_m = core::Median(ground_h);
  out.median_frame_centre_height_m = core::Median(fc_h);
  out.median_below_m = core::Median(below);
  out.median_beyond_m = core::Median(beyond);
  out.median_height_chi = core::Median(height_chi);
  out.max_chi_used = o.max_chi;
  out.datum_name = VerticalDatumName(datum);
  out.verdict = out.median_chi <= o.max_chi && out.median_height_chi <= o.max_chi
                    ? LineOfSightCheck::Verdict::kAgrees
                    : LineOfSightCheck::Verdict::kDisagrees;
  return out;
}

}  // namespace fmv3d::geo
