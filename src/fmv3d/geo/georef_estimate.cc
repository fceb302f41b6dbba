#include "fmv3d/geo/georef_estimate.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::geo {

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

bool GeorefSolution::consistent_with_telemetry() const { return fit_fraction >= min_fit_fraction; }

nlohmann::json GeorefSimilarityJson(const core::Sim3& s) {
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

namespace {

// Expected accuracy: rotation from every measurement weighed, translation and scale from the positions, or from
// their fusion with the frame centres (then at the frame centres' centroid).
GeorefAccuracy ExpectedAccuracy(const GeorefSolution& g, const std::vector<Eigen::Vector3d>& dst) {
  const double sigma = g.fit.sigma, n_eff = g.effective_samples;
  std::vector<Eigen::Vector3d> dst_in;
  for (size_t i = 0; i < dst.size(); ++i)
    if (g.fit.inliers[i]) dst_in.push_back(dst[i]);
  const double sigma_eff = sigma * std::sqrt(static_cast<double>(g.fit_inliers) / n_eff);
  GeorefAccuracy acc;
  const Eigen::Matrix3d info_positions = RotationInformation(dst_in, sigma_eff);
  Eigen::Matrix3d info = info_positions;
  acc.from.push_back("positions");
  const AttitudeFusion& att = g.attitude;
  if (!att.rotations.empty() && att.sigma_rad > 0) {
    info += Eigen::Matrix3d::Identity() * (att.effective_samples / (att.sigma_rad * att.sigma_rad));
    acc.from.push_back("attitudes");
  }
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : dst_in) centroid += p;
  centroid /= static_cast<double>(std::max<size_t>(1, dst_in.size()));
  const GeorefFrameCentres& fc = g.frame_centres;
  if (fc.used() && !fc.points.empty()) {
    info += RotationInformation(fc.points, fc.sigma);
    acc.from.push_back("frame centres");
    acc.pivot = Eigen::Vector3d::Zero();
    for (const auto& p : fc.points) acc.pivot += p;
    acc.pivot /= static_cast<double>(fc.points.size());
    Eigen::Matrix<double, 3, 4> J;
    J.col(0) = (acc.pivot - g.sim.t) / g.sim.s;
    J.rightCols<3>().setIdentity();
    acc.position_cov = J * fc.fusion->fused.covariance * J.transpose();
    acc.scale_sigma_rel = std::sqrt(std::max(0.0, fc.fusion->fused.covariance(0, 0))) / g.sim.s;
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
  acc.rotation_known = g.roll_source == RollSource::kCameraPositions || fc.used();
  acc.rotation_known =
      acc.rotation_known && eig.eigenvalues().allFinite() && eig.eigenvalues().minCoeff() > 1 / (five_deg * five_deg);
  if (acc.rotation_known) acc.rotation_cov = info.inverse();
  return acc;
}

// Residuals of the registered keyframes; with a track fit, a keyframe is an inlier within the fit's bound, else
// the fit's own mask.
std::vector<KeyframeResidual> KeyframeResiduals(const GeorefSolution& g, const PairedTelemetry& paired,
                                                const LocalFrame& frame) {
  std::vector<KeyframeResidual> out;
  for (size_t i = 0; i < paired.keyframes.size(); ++i) {
    const auto& p = paired.keyframes[i];
    KeyframeResidual r;
    r.name = p.name;
    r.enu_error = g.sim.Apply(p.centre) - frame.ToEnu(p.pos);
    r.inlier = g.use_track ? r.enu_error.norm() <= g.inlier_bound_m : static_cast<bool>(g.fit.inliers[i]);
    out.push_back(r);
  }
  return out;
}

}  // namespace

GeorefSolution EstimateGeoref(const PairedTelemetry& paired, const std::vector<Eigen::Vector3d>& model_points,
                              const GeoPoint& origin, bool origin_given, const GeorefOptions& o) {
  GeorefSolution g;
  g.origin = origin, g.origin_given = origin_given, g.datum = paired.datum;
  g.use_track = paired.use_track(), g.track_file = paired.track_file;
  g.track_samples = paired.track_samples, g.track_spanned = paired.track_spanned;
  g.min_fit_fraction = o.min_fit_fraction;
  const LocalFrame frame(origin);
  const std::vector<GeorefPair>& pairs = paired.fit();
  std::vector<Eigen::Vector3d> src, dst;
  for (const auto& p : pairs) src.push_back(p.centre), dst.push_back(frame.ToEnu(p.pos));
  geometry::SimilarityLMedSOptions lo;
  lo.max_samples = o.max_samples, lo.min_inlier_threshold = o.min_inlier_threshold, lo.seed = o.seed;
  try {
    g.fit = geometry::EstimateSimilarityLMedS(src, dst, lo);
  } catch (const Error& e) {
    throw Error(fmt::format("georef: {} ({} camera/telemetry pairs)", e.what(), src.size()));
  }
  const double sigma = g.fit.sigma;
  const RollLevelling roll = LevelRollFromGround(g.fit.sim, src, dst, sigma, model_points);
  g.roll_source = roll.source;
  if (roll.source == RollSource::kGroundPlane)
    spdlog::warn("georef: nearly straight track; the roll about it is taken from the level ground plane");
  g.sim = roll.sim;
  if (roll.source == RollSource::kCameraPositions) {
    g.attitude = FuseAttitude(g.sim, pairs, src, dst, g.fit.inliers, sigma);
    g.sim = g.attitude.sim;
  }
  if (o.use_frame_centres) {
    g.frame_centres = FuseGeorefFrameCentres({g.sim, src, dst, g.fit.inliers, sigma}, paired, g.attitude, frame,
                                             o.min_inlier_threshold);
    g.sim = g.frame_centres.sim;
  }
  g.inlier_bound_m = std::max(o.min_inlier_threshold, 3.5 * sigma);
  g.keyframes = KeyframeResiduals(g, paired, frame);
  std::vector<Eigen::Vector3d> fit_res(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) fit_res[i] = g.sim.Apply(src[i]) - dst[i];
  g.fit_pairs = pairs.size();
  g.fit_inliers = static_cast<size_t>(std::count(g.fit.inliers.begin(), g.fit.inliers.end(), 1));
  g.autocorrelation = g.use_track ? ResidualAutocorrelation(pairs, fit_res, g.fit.inliers) : 0.0;
  g.effective_samples =
      std::max(1.0, static_cast<double>(g.fit_inliers) * (1 - g.autocorrelation) / (1 + g.autocorrelation));
  g.expected_translation_error_m =
      g.frame_centres.used() ? g.frame_centres.TranslationError() : sigma * std::sqrt(3.0 / g.effective_samples);
  g.accuracy = ExpectedAccuracy(g, dst);
  g.fit_fraction = pairs.empty() ? 0.0 : static_cast<double>(g.fit_inliers) / pairs.size();
  return g;
}

nlohmann::json GeorefSolution::ToJson() const {
  const LocalFrame frame(origin);
  nlohmann::json j;
  j["version"] = 1;
  j["origin"] = {{"lat", origin.lat}, {"lon", origin.lon}, {"alt", origin.alt}};
  j["origin_source"] = origin_given ? "option" : "telemetry centroid";
  j["vertical_datum"] = VerticalDatumName(datum);
  j["frame"] = "local East-North-Up (topocentric) metres at origin: x east, y north, z up";
  j["similarity"] = GeorefSimilarityJson(sim);
  j["rotation_about_track_from"] = RollSourceName(roll_source);
  j["attitude"] = attitude.ToJson();
  j["frame_centres"] = frame_centres.ToJson();
  std::vector<double> res;
  nlohmann::json per = nlohmann::json::array();
  for (const auto& k : keyframes) {
    const Eigen::Vector3d& d = k.enu_error;
    per.push_back(
        {{"name", k.name}, {"residual_m", d.norm()}, {"enu_error", {d.x(), d.y(), d.z()}}, {"inlier", k.inlier}});
    if (k.inlier) res.push_back(d.norm());
  }
  j["residuals"] = {{"rms_m", core::Rms(res)},
                    {"median_m", core::Median(res)},
                    {"max_m", res.empty() ? 0.0 : *std::max_element(res.begin(), res.end())},
                    {"sigma_per_axis_m", fit.sigma},
                    {"per_image", per}};
  j["cameras"] = keyframes.size();
  j["inliers"] = res.size();
  nlohmann::json track = {{"used", false}};
  if (track_file) track = {{"samples", track_samples}, {"inside_registered_span", track_spanned}, {"used", use_track}};
  track["pairs"] = fit_pairs;
  track["inliers"] = fit_inliers;
  track["residual_autocorrelation"] = autocorrelation;
  track["effective_samples"] = effective_samples;
  track["from"] = use_track ? "every telemetry packet vs the model trajectory at its time" : "keyframes";
  j["fit"] = track;
  j["expected_translation_error_m"] = expected_translation_error_m;
  j["expected_accuracy"] = accuracy.ToJson();
  j["consistent_with_telemetry"] = consistent_with_telemetry();
  j["fit_fraction"] = fit_fraction;
  AddLocalFrameJson(frame, &j);
  return j;
}

void AddLocalFrameJson(const LocalFrame& frame, nlohmann::json* georef) {
  nlohmann::json& j = *georef;
  const UtmZone zone = frame.utm_zone();
  j["utm"] = {{"zone", zone.zone}, {"north", zone.north}, {"epsg", zone.Epsg()}, {"name", zone.Name()}};
  j["proj"] = {
      {"enu_from_wgs84", frame.EnuPipeline()}, {"utm_from_wgs84", frame.UtmPipeline()}, {"wgs84_crs", "EPSG:4979"}};
  j["to_wgs84"] = "WGS84 (lon, lat, h) = inverse of proj.enu_from_wgs84 applied to X_enu";
  j["wkt_utm"] = UtmWkt(zone);
}

}  // namespace fmv3d::geo
