#include "fmv3d/sfm/self_calibration.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

#include "fmv3d/sfm/mapper_primitives.h"

namespace fmv3d::sfm {

const char* ToString(IntrinsicGroup group) {
  switch (group) {
    case IntrinsicGroup::kFocal:
      return "focal";
    case IntrinsicGroup::kPrincipalPoint:
      return "principal_point";
    case IntrinsicGroup::kAspect:
      return "aspect";
    case IntrinsicGroup::kTangential:
      return "tangential";
    case IntrinsicGroup::kK1:
      return "k1";
    case IntrinsicGroup::kK2:
      return "k2";
  }
  return "?";
}

const char* IntrinsicName(core::IntrinsicIndex p) {
  static const char* kNames[core::kNumIntrinsics] = {"f", "aspect", "u0", "v0", "k1", "k2", "p1", "p2"};
  return p >= 0 && p < core::kNumIntrinsics ? kNames[p] : "?";
}

const char* ToString(NestedModelDecision decision) {
  switch (decision) {
    case NestedModelDecision::kFreed:
      return "freed";
    case NestedModelDecision::kNotSignificant:
      return "held: not significant";
    case NestedModelDecision::kUndetermined:
      return "held: not determined by the data";
    case NestedModelDecision::kFailed:
      return "held: test failed";
  }
  return "?";
}

std::vector<core::IntrinsicIndex> Parameters(IntrinsicGroup group) {
  switch (group) {
    case IntrinsicGroup::kFocal:
      return {core::kF};
    case IntrinsicGroup::kPrincipalPoint:
      return {core::kU0, core::kV0};
    case IntrinsicGroup::kAspect:
      return {core::kAspect};
    case IntrinsicGroup::kTangential:
      return {core::kP1, core::kP2};
    case IntrinsicGroup::kK1:
      return {core::kK1};
    case IntrinsicGroup::kK2:
      return {core::kK2};
  }
  return {};
}

void SetRefine(IntrinsicGroup group, bool refine, BundleAdjustmentOptions* o) {
  switch (group) {
    case IntrinsicGroup::kFocal:
      o->refine_focal = refine;
      break;
    case IntrinsicGroup::kPrincipalPoint:
      o->refine_principal_point = refine;
      break;
    case IntrinsicGroup::kAspect:
      o->refine_aspect = refine;
      break;
    case IntrinsicGroup::kTangential:
      o->refine_tangential = refine;
      break;
    case IntrinsicGroup::kK1:
      o->refine_k1 = refine;
      break;
    case IntrinsicGroup::kK2:
      o->refine_k2 = refine;
      break;
  }
}

double CornerDisplacementPerUnit(const core::Camera& c, core::IntrinsicIndex p) {
  // A point at the image corner: normalised (x, y) = half the image over the focal.
  const double x = 0.5 * c.width / c.fx(), y = 0.5 * c.height / c.fy(), r2 = x * x + y * y;
  switch (p) {
    case core::kF:
      return std::hypot(c.aspect * x, y);  // u = f·s·x + u0, v = f·y + v0
    case core::kAspect:
      return c.f * x;
    case core::kU0:
    case core::kV0:
      return 1;
    case core::kK1:
      return c.f * std::sqrt(r2) * r2;
    case core::kK2:
      return c.f * std::sqrt(r2) * r2 * r2;
    case core::kP1:
      return c.f * std::hypot(2 * x * y, r2 + 2 * y * y);
    case core::kP2:
      return c.f * std::hypot(r2 + 2 * x * x, 2 * x * y);
    default:
      return 0;
  }
}

std::vector<core::IntrinsicIndex> FreeIntrinsics(const BundleAdjustmentOptions& o) {
  std::vector<core::IntrinsicIndex> out;
  if (o.refine_focal) out.push_back(core::kF);
  if (o.refine_aspect) out.push_back(core::kAspect);
  if (o.refine_principal_point) out.insert(out.end(), {core::kU0, core::kV0});
  if (o.refine_k1) out.push_back(core::kK1);
  if (o.refine_k2) out.push_back(core::kK2);
  if (o.refine_tangential) out.insert(out.end(), {core::kP1, core::kP2});
  return out;
}

IntrinsicsPosterior DescribePosterior(const core::Camera& camera, const std::vector<core::IntrinsicIndex>& free,
                                      const Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics>* cov,
                                      double weak_corner_px) {
  IntrinsicsPosterior out;
  out.camera_id = camera.id;
  out.weak_corner_px = weak_corner_px;
  out.determined = cov != nullptr;
  const auto values = camera.Params();
  const int n = static_cast<int>(free.size());
  Eigen::MatrixXd corner(n, n);  // the covariance in corner pixels
  for (int i = 0; i < n; ++i) {
    IntrinsicUncertainty u;
    u.parameter = free[i];
    u.value = values[free[i]];
    if (cov) {
      u.sigma = std::sqrt(std::max(0.0, (*cov)(free[i], free[i])));
      u.corner_sigma_px = u.sigma * CornerDisplacementPerUnit(camera, free[i]);
      u.weak = u.corner_sigma_px > weak_corner_px;
      for (int j = 0; j < n; ++j)
        corner(i, j) = (*cov)(free[i], free[j]) * CornerDisplacementPerUnit(camera, free[i]) *
                       CornerDisplacementPerUnit(camera, free[j]);
    }
    out.parameters.push_back(u);
  }
  if (!cov || n == 0) return out;
  out.correlation = Eigen::MatrixXd::Identity(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double s = out.parameters[i].sigma * out.parameters[j].sigma;
      if (i != j && s > 0) out.correlation(i, j) = (*cov)(free[i], free[j]) / s;
    }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(corner);
  out.weakest_corner_sigma_px = std::sqrt(std::max(0.0, eig.eigenvalues()[n - 1]));
  Eigen::VectorXd d = eig.eigenvectors().col(n - 1);
  Eigen::Index largest = 0;
  d.cwiseAbs().maxCoeff(&largest);
  if (d[largest] < 0) d = -d;  // a stable sign: the dominant parameter positive
  out.weakest_direction.assign(d.data(), d.data() + n);
  return out;
}

namespace {

// LM damping of diag(JᵀJ) · 1e-12 at the first step: below a near-gauge direction's curvature, far above round-off.
constexpr double kNearOptimumTrustRegion = 1e12;

// Leaves out of *rec the observations outside the Gaussian core of the reprojection errors: the core's σ per axis
// from the median 2D error (for Gaussian errors it is Rayleigh-distributed, median σ·√(2 ln 2)), the bound where a
// χ²(2) exceeds 1 − core_mass. Returns (observations left out, σ).
std::pair<int, double> KeepGaussianCore(core::Reconstruction* rec, double core_mass) {
  std::vector<double> errors;
  for (const auto& [pid, p] : rec->points)
    for (const auto& el : p.track) errors.push_back(ObservationError(*rec, el.image_id, el.point2d_idx, p.xyz));
  if (errors.empty()) return {0, 0};
  auto mid = errors.begin() + errors.size() / 2;
  std::nth_element(errors.begin(), mid, errors.end());
  const double sigma = *mid / std::sqrt(2 * std::log(2.0));
  const double bound = sigma * std::sqrt(-2 * std::log(1 - core_mass));
  const int kept = static_cast<int>(std::count_if(errors.begin(), errors.end(), [&](double e) { return e <= bound; }));
  FilterPoints(rec, nullptr, {bound, 0.0});
  return {static_cast<int>(errors.size()) - kept, sigma};
}

}  // namespace

NestedModelTestResult TestNestedModel(core::Reconstruction* rec, const BundleAdjustmentConfig& config,
                                      BundleAdjustmentOptions options, IntrinsicGroup group,
                                      const NestedModelTestOptions& test_options) {
  NestedModelTestResult r;
  r.group = group;
  r.parameters = Parameters(group);
  r.num_parameters = static_cast<int>(r.parameters.size());
  options.loss = BundleAdjustmentOptions::Loss::kTrivial;  // χ² needs plain squared errors (outliers are filtered)
  core::Reconstruction held = *rec;
  SetRefine(group, false, &options);
  options.compute_intrinsics_covariance = false;
  auto s0 = BundleAdjust(&held, config, options);
  if (!s0.success || held.cameras.empty()) return r;
  // From here on each fit starts at a neighbouring optimum: nearly Gauss–Newton steps (initial_trust_region_radius).
  // The core is that of the null model's fit (outliers are defined under the hypothesis tested); the held fit
  // then continues on it from where it stopped.
  options.initial_trust_region_radius = std::max(options.initial_trust_region_radius, kNearOptimumTrustRegion);
  if (test_options.core_mass < 1) {
    std::tie(r.observations_left_out, r.core_sigma_px) = KeepGaussianCore(&held, test_options.core_mass);
    s0 = BundleAdjust(&held, config, options);
    if (!s0.success) return r;
  }
  core::Reconstruction freed = held;  // starts at the held optimum: a few steps only
  SetRefine(group, true, &options);
  options.compute_intrinsics_covariance = test_options.require_determined;
  const auto s1 = BundleAdjust(&freed, config, options);
  if (!s1.success) return r;
  const double n = s0.num_residuals;
  const double ss0 = s0.final_rms_px * s0.final_rms_px * n, ss1 = s1.final_rms_px * s1.final_rms_px * n;
  r.num_observations = s0.num_residuals;
  r.dof = std::max(1.0, 2 * n - 6.0 * held.images.size() - 3.0 * held.points.size());
  r.delta_chi2 = (ss0 - ss1) / std::max(ss0 / r.dof, 1e-12);
  r.threshold =
      test_options.min_delta_chi2 > 0 ? test_options.min_delta_chi2 : r.num_parameters * std::log(std::max(2.0, 2 * n));
  r.fixed_threshold = test_options.min_delta_chi2 > 0;
  r.rms_held_px = s0.final_rms_px;
  r.rms_freed_px = s1.final_rms_px;
  const uint32_t cid = held.cameras.begin()->first;
  r.held = held.cameras.begin()->second;
  r.freed = freed.cameras.begin()->second;
  const auto held_params = r.held.Params(), freed_params = r.freed.Params();
  for (auto p : r.parameters) {
    r.held_values.push_back(held_params[p]);
    r.freed_values.push_back(freed_params[p]);
  }
  if (!(r.freed.f > 0)) return r;
  if (r.delta_chi2 <= r.threshold) {
    r.decision = NestedModelDecision::kNotSignificant;
    return r;
  }
  if (test_options.require_determined) {
    auto cov = s1.intrinsics_covariance.find(cid);
    if (cov == s1.intrinsics_covariance.end()) return r;  // rank-deficient: not determined either
    // "Determined": bias against variance. Holding the group costs the squared shift the data ask for (its bias,
    // Σ Δθ²), freeing it costs its variance (Σ σ_θ²): the group is freed when the first exceeds the second. A group
    // the data leave uncertain (a principal point trading against a common tilt of the cameras, a focal on a
    // telephoto plateau) would only move the cameras by its uncertainty: it stays held. Summed over the group (its
    // parameters share a unit), not required of each: a principal point off-centre along one axis only has the
    // other coordinate at its prior, where it rightly moves by less than its σ.
    double bias2 = 0, variance = 0;
    for (size_t i = 0; i < r.parameters.size(); ++i) {
      const auto p = r.parameters[i];
      const double sigma = std::sqrt(std::max(0.0, cov->second(p, p)));
      r.sigmas.push_back(sigma);
      r.max_sigma_px = std::max(r.max_sigma_px, sigma * CornerDisplacementPerUnit(r.freed, p));
      bias2 += (r.freed_values[i] - r.held_values[i]) * (r.freed_values[i] - r.held_values[i]);
      variance += sigma * sigma;
    }
    const bool determined = variance < bias2;
    if (!determined) {
      r.decision = NestedModelDecision::kUndetermined;
      return r;
    }
  }
  r.decision = NestedModelDecision::kFreed;
  // The fits ran on the core only: the caller's model keeps every observation and takes the freed intrinsics.
  for (auto& [id, cam] : rec->cameras) cam = freed.cameras.at(id);
  return r;
}

}  // namespace fmv3d::sfm
