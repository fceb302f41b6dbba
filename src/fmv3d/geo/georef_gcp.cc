#include "fmv3d/geo/georef_gcp.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geo/georef_estimate.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::geo {

void GcpGeorefOptions::Check() const {
  if (min_control_points < 3) throw Error("georef: a GCP fit needs at least 3 control points");
  if (!(gcp_sigma_m > 0)) throw Error("georef: the GCPs' σ must be positive");
}

const char* GcpStatusName(GcpStatus s) {
  switch (s) {
    case GcpStatus::kControl:
      return "control";
    case GcpStatus::kCheck:
      return "check";
    case GcpStatus::kTooFewFrames:
      return "fewer than 2 registered frames";
    case GcpStatus::kNotTriangulated:
      return "rays do not meet in front of the cameras";
  }
  return "";
}

namespace {

// Triangulates one GCP from its observations in registered images; false when it cannot.
bool Triangulate(const core::Reconstruction& model, const GroundControlPoint& gcp, GcpResult* r) {
  std::vector<core::Pose> poses;
  std::vector<Eigen::Vector2d> normalized, pixels;
  std::vector<const core::Camera*> cameras;
  for (const auto& o : gcp.observations) {
    const core::Image* im = model.FindImageByName(o.frame);
    if (!im) continue;
    const core::Camera& cam = model.cameras.at(im->camera_id);
    poses.push_back(im->pose);
    normalized.push_back(cam.Unproject({o.x, o.y}).hnormalized());
    pixels.emplace_back(o.x, o.y);
    cameras.push_back(&cam);
  }
  r->registered_observations = static_cast<int>(poses.size());
  if (poses.size() < 2) {
    r->status = GcpStatus::kTooFewFrames;
    return false;
  }
  Eigen::Vector3d X;
  if (!geometry::TriangulateDLT(poses, normalized, &X)) {
    r->status = GcpStatus::kNotTriangulated;
    return false;
  }
  geometry::RefinePoint(poses, normalized, &X, 10);
  double sse = 0;
  for (size_t k = 0; k < poses.size(); ++k) {
    const Eigen::Vector3d xc = poses[k].Transform(X);
    if (xc.z() <= 0) {
      r->status = GcpStatus::kNotTriangulated;
      return false;
    }
    sse += (cameras[k]->Project(xc) - pixels[k]).squaredNorm();
  }
  // Precision of the point for a 1 px click: Σ = (Σ_k J_kᵀ J_k)⁻¹, J_k = d(pixel)/dX through camera k.
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  for (size_t k = 0; k < poses.size(); ++k) {
    const Eigen::Matrix<double, 2, 3> J =
        cameras[k]->ProjectJacobian(poses[k].Transform(X)) * poses[k].q.toRotationMatrix();
    info += J.transpose() * J;
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(info);
  r->sigma_per_px = lu.isInvertible() ? std::sqrt(lu.inverse().trace()) : std::numeric_limits<double>::infinity();
  r->triangulated = X;
  r->reprojection_px = std::sqrt(sse / poses.size());
  r->status = gcp.check ? GcpStatus::kCheck : GcpStatus::kControl;
  return true;
}

double Rms3d(const std::vector<GcpResult>& points, GcpStatus status, int* n) {
  double sse = 0;
  *n = 0;
  for (const auto& p : points)
    if (p.status == status) {
      sse += p.residual_enu.squaredNorm();
      ++*n;
    }
  return *n ? std::sqrt(sse / *n) : 0.0;
}

// RMS reprojection error (pixels) of the observations of the points `known` at the given positions.
double ClickRms(const core::Reconstruction& rec, const std::map<uint64_t, Eigen::Vector3d>& known) {
  double sse = 0;
  size_t n = 0;
  for (const auto& [id, X] : known)
    for (const auto& el : rec.points.at(id).track) {
      const double e = sfm::ObservationError(rec, el.image_id, el.point2d_idx, X);
      sse += e * e;
      ++n;
    }
  return n ? std::sqrt(sse / n) : 0.0;
}

// Step 4 (georef_gcp.h) on `enu`, the model already placed by the similarity: the control points are appended as
// points with priors at their coordinates and their clicks as observations, adjusted with everything else, then
// removed again. On failure `enu` is left as it was and adj->why_not says why.
void AdjustWithGcps(const std::vector<GroundControlPoint>& gcps, const std::vector<GcpResult>& points,
                    const GcpGeorefOptions& options, core::Reconstruction* enu, GcpAdjustment* adj) {
  const auto start = std::chrono::steady_clock::now();
  core::Reconstruction rec = *enu;
  std::map<uint32_t, size_t> automatic_size;  // per image: its observations before the clicks were appended
  for (const auto& [id, im] : rec.images) automatic_size[id] = im.points2d.size();
  sfm::BundleAdjustmentConfig config;
  config.point_prior_sigma = options.gcp_sigma_m;
  uint64_t next_id = rec.points.empty() ? 1 : rec.points.rbegin()->first + 1;
  for (size_t i = 0; i < gcps.size(); ++i) {
    if (points[i].status != GcpStatus::kControl) continue;
    core::Point3D P;
    P.id = next_id++;
    P.xyz = points[i].enu;
    for (const auto& o : gcps[i].observations) {
      const core::Image* found = rec.FindImageByName(o.frame);
      if (!found) continue;
      core::Image& im = rec.images.at(found->id);
      P.track.push_back({im.id, static_cast<uint32_t>(im.points2d.size())});
      im.points2d.emplace_back(o.x, o.y);
      im.point3d_ids.push_back(static_cast<int64_t>(P.id));
    }
    adj->observations += static_cast<int>(P.track.size());
    config.point_priors[P.id] = P.xyz;
    rec.points.emplace(P.id, std::move(P));
  }
  adj->gcp_rms_px_before = ClickRms(rec, config.point_priors);
  // The clicks weigh by their accuracy against the automatic observations': (σ_auto / σ_click)², both measured.
  std::map<uint64_t, Eigen::Vector3d> automatic;
  for (const auto& [id, P] : enu->points) automatic[id] = P.xyz;
  const double auto_rms = automatic.empty() ? 1.0 : ClickRms(*enu, automatic);
  config.point_prior_observation_weight =
      adj->gcp_rms_px_before > auto_rms ? std::pow(auto_rms / adj->gcp_rms_px_before, 2) : 1.0;
  adj->click_weight = config.point_prior_observation_weight;
  sfm::BundleAdjustmentOptions bo;  // the focal is free: with the GCPs it is no longer traded against depth
  bo.refine_focal = options.refine_focal;
  bo.refine_k1 = bo.refine_k2 = false;
  const sfm::BundleAdjustmentSummary summary = sfm::BundleAdjust(&rec, config, bo);
  adj->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!summary.success) {
    adj->why_not = "the bundle adjustment did not converge";
    return;
  }
  adj->gcp_rms_px_after = ClickRms(rec, config.point_priors);
  adj->rms_px_before = summary.initial_rms_px;
  adj->rms_px_after = summary.final_rms_px;
  for (const auto& [id, X] : config.point_priors) rec.points.erase(id);
  for (auto& [id, im] : rec.images) {
    im.points2d.resize(automatic_size.at(id));
    im.point3d_ids.resize(automatic_size.at(id));
    adj->max_camera_shift_m =
        std::max(adj->max_camera_shift_m, (im.pose.Centre() - enu->images.at(id).pose.Centre()).norm());
  }
  adj->applied = true;
  *enu = std::move(rec);
}

// Step 3's datum fitted to the clicks themselves: Gauss–Newton on the seven parameters of `sim` (started from the
// precision-weighted Umeyama fit) minimising the reprojection error of every control click, the control point at
// its coordinates carried into the model by sim⁻¹ and projected by the model's camera (Huber 3 px, as in step 4).
// With the model's shape taken as exact this is the maximum-likelihood datum: each click weighs by its own geometry
// (depth, angle), where the triangulate-then-fit weighs a whole point by one scalar and discards the anisotropy of
// its triangulation (an orbit's points are far less certain along the line of sight). Returns false (sim kept)
// when it does not lower the cost.
bool FitDatumToClicks(const core::Reconstruction& model, const std::vector<GroundControlPoint>& gcps,
                      const std::vector<GcpResult>& points, core::Sim3* sim) {
  struct Click {
    const core::Image* image;
    const core::Camera* camera;
    Eigen::Vector3d enu;
    Eigen::Vector2d uv;
  };
  std::vector<Click> clicks;
  for (size_t i = 0; i < gcps.size(); ++i) {
    if (points[i].status != GcpStatus::kControl) continue;
    for (const auto& o : gcps[i].observations)
      if (const core::Image* im = model.FindImageByName(o.frame))
        clicks.push_back({im, &model.cameras.at(im->camera_id), points[i].enu, {o.x, o.y}});
  }
  constexpr double kHuberPx = 3;
  // Robust cost of `s`; with J, H and g, the Gauss–Newton system in δ = (ω, δt, δlog s), δS applied after s.
  auto evaluate = [&](const core::Sim3& s, Eigen::Matrix<double, 7, 7>* H, Eigen::Matrix<double, 7, 1>* g) {
    const core::Sim3 inv = s.Inverse();
    const Eigen::Matrix3d Rt_over_s = s.q.conjugate().toRotationMatrix() / s.s;  // d(model point)/d(ENU point)
    double cost = 0;
    if (H) H->setZero(), g->setZero();
    for (const auto& c : clicks) {
      const Eigen::Vector3d xc = c.image->pose.Transform(inv.Apply(c.enu));
      if (xc.z() <= 0) return std::numeric_limits<double>::infinity();
      const Eigen::Vector2d r = c.camera->Project(xc) - c.uv;
      const double e = r.norm(), w = e <= kHuberPx ? 1.0 : kHuberPx / e;
      cost += e <= kHuberPx ? e * e : 2 * kHuberPx * e - kHuberPx * kHuberPx;
      if (!H) continue;
      // δS⁻¹(Y) ≈ Y − δt − δlog s·Y + Y×ω: the ENU point as the perturbed datum sees it.
      const Eigen::Vector3d& Y = c.enu;
      Eigen::Matrix<double, 3, 7> dY;
      dY << 0, -Y.z(), Y.y(), -1, 0, 0, -Y.x(),  //
          Y.z(), 0, -Y.x(), 0, -1, 0, -Y.y(),    //
          -Y.y(), Y.x(), 0, 0, 0, -1, -Y.z();
      const Eigen::Matrix<double, 2, 7> J =
          c.camera->ProjectJacobian(xc) * c.image->pose.q.toRotationMatrix() * Rt_over_s * dY;
      *H += w * J.transpose() * J;
      *g += w * J.transpose() * r;
    }
    return cost;
  };
  core::Sim3 s = *sim;
  const double start_cost = evaluate(s, nullptr, nullptr);
  if (!std::isfinite(start_cost)) return false;  // a control point behind a camera: keep the Umeyama fit
  double cost = start_cost;
  for (int it = 0; it < 20; ++it) {
    Eigen::Matrix<double, 7, 7> H;
    Eigen::Matrix<double, 7, 1> g;
    evaluate(s, &H, &g);
    const Eigen::Matrix<double, 7, 1> d = H.ldlt().solve(-g);
    if (!d.allFinite()) break;
    core::Sim3 step;
    step.s = std::exp(d(6));
    const double angle = d.head<3>().norm();
    step.q =
        angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, d.head<3>() / angle)) : Eigen::Quaterniond::Identity();
    step.t = d.segment<3>(3);
    core::Sim3 next;  // step ∘ s
    next.s = step.s * s.s;
    next.q = (step.q * s.q).normalized();
    next.t = step.Apply(s.t);
    const double next_cost = evaluate(next, nullptr, nullptr);
    if (!(next_cost < cost)) break;
    const bool converged = cost - next_cost < 1e-10 * cost;
    s = next;
    cost = next_cost;
    if (converged) break;
  }
  if (!(cost < start_cost)) return false;
  *sim = s;
  return true;
}

// The similarity of the sparse model's camera centres onto the adjusted model's (same image ids).
bool FitToAdjusted(const core::Reconstruction& model, const core::Reconstruction& enu, core::Sim3* sim) {
  std::vector<Eigen::Vector3d> src, dst;
  for (const auto& [id, im] : model.images) {
    src.push_back(im.pose.Centre());
    dst.push_back(enu.images.at(id).pose.Centre());
  }
  return src.size() >= 3 && geometry::EstimateSimilarity(src, dst, std::vector<double>(src.size(), 1.0), true, sim);
}

}  // namespace

GcpGeoref EstimateGcpGeoref(const core::Reconstruction& model, const std::vector<GroundControlPoint>& gcps,
                            const GcpCrs& crs, const GcpGeorefOptions& options) {
  options.Check();
  GcpGeoref out;
  out.crs_name = crs.name();
  out.vertical_datum = crs.vertical_datum();
  std::vector<GeoPoint> wgs84;
  wgs84.reserve(gcps.size());
  for (const auto& g : gcps) wgs84.push_back(crs.ToWgs84(g.geo));
  if (options.origin) {
    out.origin = *options.origin;
    out.origin_given = true;
  } else {
    for (const auto& w : wgs84) {
      out.origin.lat += w.lat / wgs84.size();
      out.origin.lon += w.lon / wgs84.size();
      out.origin.alt += w.alt / wgs84.size();
    }
  }
  const LocalFrame frame(out.origin);
  std::vector<Eigen::Vector3d> src, dst;
  std::vector<double> weights;
  std::vector<std::string> control_names;
  for (size_t i = 0; i < gcps.size(); ++i) {
    GcpResult r;
    r.name = gcps[i].name;
    r.observations = static_cast<int>(gcps[i].observations.size());
    r.enu = frame.ToEnu(wgs84[i]);
    if (Triangulate(model, gcps[i], &r) && r.status == GcpStatus::kControl) {
      src.push_back(r.triangulated);
      dst.push_back(r.enu);
      weights.push_back(std::isfinite(r.sigma_per_px) && r.sigma_per_px > 0 ? 1 / (r.sigma_per_px * r.sigma_per_px)
                                                                            : 0);
      control_names.push_back(r.name);
    }
    out.points.push_back(std::move(r));
  }
  if (static_cast<int>(src.size()) < options.min_control_points) {
    std::string why;
    for (const auto& p : out.points)
      if (p.status != GcpStatus::kControl && p.status != GcpStatus::kCheck)
        why += fmt::format("; \"{}\": {} ({} of {} observations in registered frames)", p.name, GcpStatusName(p.status),
                           p.registered_observations, p.observations);
    throw Error(
        fmt::format("georef: {} GCP(s) could be triangulated as control points, {} needed (check points "
                    "are not used in the fit){}",
                    src.size(), options.min_control_points, why));
  }
  // Each control point weighs by its triangulation's precision (1/σ², the model's units): a GCP seen by many
  // frames from wide angles counts more than one seen by two frames close together.
  const double w_max = weights.empty() ? 0 : *std::max_element(weights.begin(), weights.end());
  if (!(w_max > 0)) weights.assign(src.size(), 1.0);
  if (!geometry::EstimateSimilarity(src, dst, weights, true, &out.sim) || geometry::Collinearity(dst) < 1e-3)
    throw Error("georef: the control points (" + fmt::format("{}", fmt::join(control_names, ", ")) +
                ") are collinear; add a GCP off their line");
  out.datum_fitted_to_clicks = options.fit_to_clicks && FitDatumToClicks(model, gcps, out.points, &out.sim);
  out.enu = model;
  out.enu.Transform(out.sim);
  if (!options.adjust) out.adjustment.why_not = "turned off";
  if (options.adjust) AdjustWithGcps(gcps, out.points, options, &out.enu, &out.adjustment);
  if (out.adjustment.applied && !FitToAdjusted(model, out.enu, &out.sim))
    throw Error("georef: no similarity between the sparse and the GCP-adjusted cameras");
  // Residuals: each point triangulated again with the final cameras (for the similarity alone this equals S·X).
  for (size_t i = 0; i < gcps.size(); ++i) {
    GcpResult& p = out.points[i];
    GcpResult again;
    if (p.triangulated_ok())
      p.residual_enu =
          (Triangulate(out.enu, gcps[i], &again) ? again.triangulated : out.sim.Apply(p.triangulated)) - p.enu;
  }
  out.control_rms_m = Rms3d(out.points, GcpStatus::kControl, &out.control_used);
  out.check_rms_m = Rms3d(out.points, GcpStatus::kCheck, &out.check_used);
  return out;
}

namespace {
nlohmann::json AdjustmentJson(const GcpAdjustment& a) {
  if (!a.applied) return {{"applied", false}, {"why_not", a.why_not}};
  return {{"applied", true},
          {"gcp_observations", a.observations},
          {"click_weight", a.click_weight},
          {"gcp_reprojection_rms_px_before", a.gcp_rms_px_before},
          {"gcp_reprojection_rms_px_after", a.gcp_rms_px_after},
          {"reprojection_rms_px_before", a.rms_px_before},
          {"reprojection_rms_px_after", a.rms_px_after},
          {"max_camera_shift_m", a.max_camera_shift_m},
          {"seconds", a.seconds}};
}
}  // namespace

nlohmann::json GcpGeoref::ToJson() const {
  const LocalFrame frame(origin);
  const double out_scale = sim.s;
  nlohmann::json j;
  j["version"] = 1;
  j["source"] = "gcp";
  j["origin"] = {{"lat", origin.lat}, {"lon", origin.lon}, {"alt", origin.alt}};
  j["origin_source"] = origin_given ? "option" : "GCP centroid";
  j["vertical_datum"] = vertical_datum;
  j["frame"] = "local East-North-Up (topocentric) metres at origin: x east, y north, z up";
  j["similarity"] = GeorefSimilarityJson(sim);
  nlohmann::json pts = nlohmann::json::array();
  for (const auto& p : points) {
    nlohmann::json e = {{"name", p.name},
                        {"status", GcpStatusName(p.status)},
                        {"check", p.status == GcpStatus::kCheck},
                        {"observations", p.observations},
                        {"registered_observations", p.registered_observations},
                        {"enu", {p.enu.x(), p.enu.y(), p.enu.z()}}};
    if (p.triangulated_ok()) {
      e["residual_m"] = p.residual_enu.norm();
      e["residual_enu_m"] = {p.residual_enu.x(), p.residual_enu.y(), p.residual_enu.z()};
      e["residual_horizontal_m"] = p.residual_enu.head<2>().norm();
      e["reprojection_px"] = p.reprojection_px;
      e["sigma_m_per_px"] = p.sigma_per_px * out_scale;
    }
    pts.push_back(e);
  }
  j["gcps"] = {
      {"crs", crs},
      {"crs_name", crs_name},
      {"vertical_datum", vertical_datum},
      {"points", pts},
      {"control_points_used", control_used},
      {"check_points_used", check_used},
      {"rms_m", control_rms_m},
      {"check_rms_m", check_used ? nlohmann::json(check_rms_m) : nlohmann::json()},
      {"fit",
       "least-squares similarity (Umeyama) of the triangulated control points to their coordinates, each "
       "weighted by 1/σ² of its triangulation (sigma_m_per_px: its σ in metres for a 1 px click), refined on the "
       "clicks' reprojection errors (datum_fitted_to_clicks), then a bundle "
       "adjustment with the control points held at their coordinates and their clicks as reprojection residuals "
       "(adjustment); residuals from the points triangulated again with the final cameras"},
      {"datum_fitted_to_clicks", datum_fitted_to_clicks},
      {"adjustment", AdjustmentJson(adjustment)},
      {"independent_accuracy", check_used ? "check_rms_m: check points left out of the fit"
                                          : "none: mark GCPs as check points (extra field \"check\") to measure it"}};
  // The keys the telemetry georeference writes and later stages read.
  j["cameras"] = 0;
  j["inliers"] = control_used;
  j["residuals"] = {{"rms_m", control_rms_m}, {"per_gcp", "see gcps.points"}};
  j["consistent_with_telemetry"] = true;
  j["telemetry"] = "not used: GCPs outrank telemetry";
  j["trusted"] = true;
  AddLocalFrameJson(frame, &j);
  return j;
}

}  // namespace fmv3d::geo
