#include "fmv3d/sfm/bundle_adjustment.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/ceres.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <memory>

#include "fmv3d/core/error.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/geometry/reprojection_error.h"

namespace fmv3d::sfm {

void BundleAdjustmentOptions::Check() const {
  if (!(loss_scale_px > 0)) throw Error("bundle adjustment: loss_scale_px must be > 0");
  if (max_iterations < 1) throw Error("bundle adjustment: max_iterations must be ≥ 1");
  if (!(function_tolerance > 0)) throw Error("bundle adjustment: function_tolerance must be > 0");
}

double ObservationError(const core::Reconstruction& rec, uint32_t image_id, uint32_t point2d_idx,
                        const Eigen::Vector3d& xyz) {
  const auto& image = rec.images.at(image_id);
  const auto& cam = rec.cameras.at(image.camera_id);
  const Eigen::Vector3d x = image.pose.Transform(xyz);
  if (x.z() <= 0) return std::numeric_limits<double>::infinity();
  return (cam.Project(x) - image.points2d[point2d_idx]).norm();
}

void UpdatePointErrors(core::Reconstruction* rec) {
  for (auto& [id, p] : rec->points) {
    double sum = 0;
    for (const auto& el : p.track) sum += ObservationError(*rec, el.image_id, el.point2d_idx, p.xyz);
    p.error = p.track.empty() ? 0 : sum / p.track.size();
  }
}

namespace {

// w · (t[k] − t0): holds one translation coordinate (the gauge of scale), weighted relative to its size.
class ScaleGaugePrior : public ceres::SizedCostFunction<1, 3> {
 public:
  ScaleGaugePrior(int k, double t0) : k_(k), t0_(t0), w_(1e3 / std::max(std::abs(t0), 1e-9)) {}
  bool Evaluate(double const* const* params, double* residual, double** jacobians) const override {
    residual[0] = w_ * (params[0][k_] - t0_);
    if (jacobians && jacobians[0]) {
      jacobians[0][0] = jacobians[0][1] = jacobians[0][2] = 0;
      jacobians[0][k_] = w_;
    }
    return true;
  }

 private:
  int k_;
  double t0_, w_;
};

// (C − prior) / σ with C = −Rᵀt, the camera centre of pose (q, t) (q in Eigen's x y z w order).
struct CentrePrior {
  CentrePrior(const Eigen::Vector3d& prior, double sigma) : prior_(prior), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, const T* t, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> c = -(rot.conjugate() * Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]));
    for (int k = 0; k < 3; ++k) residual[k] = (c[k] - T(prior_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d prior_;
  double inv_sigma_;
};

// (Rᵀ·z − axis) / σ: the optical axis of pose q (world-to-camera, Eigen x y z w order) in the world frame.
struct AxisPrior {
  AxisPrior(const Eigen::Vector3d& axis, double sigma) : axis_(axis.normalized()), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> z = rot.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    for (int k = 0; k < 3; ++k) residual[k] = (z[k] - T(axis_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d axis_;
  double inv_sigma_;
};

// (C + r·Rᵀ·z − F) / σ: the point at range r along the optical axis of pose (q, t), against a frame centre F.
struct SightPrior {
  SightPrior(const Eigen::Vector3d& frame_centre, double range, double sigma)
      : f_(frame_centre), range_(range), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, const T* t, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> c = -(rot.conjugate() * Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]));
    const Eigen::Matrix<T, 3, 1> z = rot.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    for (int k = 0; k < 3; ++k) residual[k] = (c[k] + T(range_) * z[k] - T(f_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d f_;
  double range_, inv_sigma_;
};

struct PoseBlock {
  std::array<double, 4> q;  // Eigen order x y z w
  std::array<double, 3> t;
};

}  // namespace

BundleAdjustmentSummary BundleAdjust(core::Reconstruction* rec, const BundleAdjustmentConfig& config,
                                     const BundleAdjustmentOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  BundleAdjustmentSummary out;
  if (rec->images.size() < 2) return out;

  std::set<uint32_t> variable = config.variable_images;
  if (variable.empty())
    for (const auto& [id, im] : rec->images) variable.insert(id);

  // Points seen by a variable image, and every image observing them.
  std::vector<uint64_t> point_ids;
  for (uint32_t id : variable) {
    auto it = rec->images.find(id);
    if (it == rec->images.end()) continue;
    for (int64_t pid : it->second.point3d_ids)
      if (pid != core::kNoPoint3D) point_ids.push_back(static_cast<uint64_t>(pid));
  }
  std::sort(point_ids.begin(), point_ids.end());
  point_ids.erase(std::unique(point_ids.begin(), point_ids.end()), point_ids.end());
  if (point_ids.empty()) return out;

  // Parameter and cost blocks live in flat arrays owned here (the problem does not own them): a global
  // adjustment has hundreds of thousands of residuals, and one allocation each (plus Ceres' bookkeeping of
  // owned objects) was a visible share of a short adjustment's time.
  std::map<uint32_t, PoseBlock> poses;
  std::map<uint32_t, std::array<double, core::kNumIntrinsics>> intr;
  std::vector<std::array<double, 3>> pts(point_ids.size());
  size_t num_obs = 0;
  for (uint64_t pid : point_ids) num_obs += rec->points.at(pid).track.size();
  std::deque<geometry::AnalyticReprojectionError> costs;  // stable addresses, allocated in chunks
  ceres::EigenQuaternionManifold quaternion_manifold;
  ceres::Problem::Options popts;
  popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // shared_loss below outlives the problem
  popts.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // costs above
  popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;       // quaternion_manifold, subset_manifolds
  // One loss object for every residual: hundreds of thousands of residuals in a global adjustment would
  // otherwise mean as many allocations. Declared before the problem, so it is destroyed after it.
  std::unique_ptr<ceres::LossFunction> shared_loss;
  switch (options.loss) {
    case BundleAdjustmentOptions::Loss::kCauchy:
      shared_loss.reset(new ceres::CauchyLoss(options.loss_scale_px));
      break;
    case BundleAdjustmentOptions::Loss::kHuber:
      shared_loss.reset(new ceres::HuberLoss(options.loss_scale_px));
      break;
    default:
      break;
  }
  std::unique_ptr<ceres::LossFunction> weighted_loss;
  if (!config.weighted_from.empty() && config.observation_weight != 1) {
    if (!(config.observation_weight > 0)) throw Error("bundle adjustment: observation_weight must be positive");
    weighted_loss = std::make_unique<ceres::ScaledLoss>(shared_loss.get(), config.observation_weight,
                                                        ceres::DO_NOT_TAKE_OWNERSHIP);
  }
  std::vector<std::unique_ptr<ceres::Manifold>> subset_manifolds;
  std::unique_ptr<ceres::CostFunction> gauge_prior;
  ceres::Problem problem(popts);

  auto loss = [&]() { return shared_loss.get(); };
  auto loss_of = [&](uint32_t image_id, uint32_t point2d_idx) {
    if (weighted_loss) {
      const auto w = config.weighted_from.find(image_id);
      if (w != config.weighted_from.end() && point2d_idx >= w->second) return weighted_loss.get();
    }
    return loss();
  };

  // Per residual: (image, point2d) for the caller and the parameter blocks, to evaluate the plain RMS directly
  // (ceres::Problem::Evaluate builds a whole program for it: measured ~10% of a local adjustment).
  std::vector<std::pair<uint32_t, uint32_t>> residual_obs;
  std::vector<std::array<double*, 4>> residual_params;
  residual_obs.reserve(num_obs);
  residual_params.reserve(num_obs);
  for (size_t i = 0; i < point_ids.size(); ++i) {
    auto& P = rec->points.at(point_ids[i]);
    auto& X = pts[i];
    X = {P.xyz.x(), P.xyz.y(), P.xyz.z()};
    for (const auto& el : P.track) {
      auto& image = rec->images.at(el.image_id);
      auto pit = poses.find(el.image_id);
      if (pit == poses.end()) {
        PoseBlock b;
        b.q = {image.pose.q.x(), image.pose.q.y(), image.pose.q.z(), image.pose.q.w()};
        b.t = {image.pose.t.x(), image.pose.t.y(), image.pose.t.z()};
        pit = poses.emplace(el.image_id, b).first;
      }
      auto cit = intr.find(image.camera_id);
      if (cit == intr.end()) cit = intr.emplace(image.camera_id, rec->cameras.at(image.camera_id).Params()).first;
      costs.emplace_back(image.points2d[el.point2d_idx]);
      residual_params.push_back({cit->second.data(), pit->second.q.data(), pit->second.t.data(), X.data()});
      problem.AddResidualBlock(&costs.back(), loss_of(el.image_id, el.point2d_idx), residual_params.back().data(), 4);
      residual_obs.emplace_back(el.image_id, el.point2d_idx);
    }
    if (!options.refine_points) problem.SetParameterBlockConstant(X.data());
  }

  // Poses: variable unless constant or outside the variable set; gauge fixed when nothing else anchors it.
  bool any_constant = false;
  for (auto& [id, b] : poses) {
    problem.SetManifold(b.q.data(), &quaternion_manifold);
    if (!variable.count(id) || config.constant_images.count(id)) {
      problem.SetParameterBlockConstant(b.q.data());
      problem.SetParameterBlockConstant(b.t.data());
      any_constant = true;
    }
  }
  // Centre priors (see the header): they anchor the gauge when at least three variable images have one.
  std::vector<std::unique_ptr<ceres::CostFunction>> prior_costs;
  std::unique_ptr<ceres::LossFunction> prior_loss;
  size_t centre_prior_count = 0;
  if (!config.centre_priors.empty()) {
    if (!(config.centre_prior_sigma > 0)) throw Error("bundle adjustment: centre_prior_sigma must be positive");
    prior_loss = std::make_unique<ceres::HuberLoss>(config.centre_prior_huber);
    for (const auto& [id, c] : config.centre_priors) {
      const auto it = poses.find(id);
      if (it == poses.end() || !variable.count(id) || config.constant_images.count(id)) continue;
      prior_costs.emplace_back(
          new ceres::AutoDiffCostFunction<CentrePrior, 3, 4, 3>(new CentrePrior(c, config.centre_prior_sigma)));
      problem.AddResidualBlock(prior_costs.back().get(), prior_loss.get(), it->second.q.data(), it->second.t.data());
      ++centre_prior_count;
    }
  }
  if (!config.axis_priors.empty()) {
    if (!(config.axis_prior_sigma_rad > 0)) throw Error("bundle adjustment: axis_prior_sigma_rad must be positive");
    for (const auto& [id, axis] : config.axis_priors) {
      const auto it = poses.find(id);
      if (it == poses.end() || !variable.count(id) || config.constant_images.count(id)) continue;
      prior_costs.emplace_back(
          new ceres::AutoDiffCostFunction<AxisPrior, 3, 4>(new AxisPrior(axis, config.axis_prior_sigma_rad)));
      problem.AddResidualBlock(prior_costs.back().get(), nullptr, it->second.q.data());
    }
  }
  std::unique_ptr<ceres::LossFunction> sight_loss;
  if (!config.sight_priors.empty()) {
    if (!(config.sight_prior_sigma > 0)) throw Error("bundle adjustment: sight_prior_sigma must be positive");
    sight_loss = std::make_unique<ceres::HuberLoss>(3.0);
    size_t sight_count = 0;
    for (const auto& [id, fr] : config.sight_priors) {
      const auto it = poses.find(id);
      if (it == poses.end() || !variable.count(id) || config.constant_images.count(id)) continue;
      prior_costs.emplace_back(new ceres::AutoDiffCostFunction<SightPrior, 3, 4, 3>(
          new SightPrior(fr.first, fr.second, config.sight_prior_sigma)));
      problem.AddResidualBlock(prior_costs.back().get(), sight_loss.get(), it->second.q.data(), it->second.t.data());
      ++sight_count;
    }
    if (sight_count >= 3) centre_prior_count = std::max<size_t>(centre_prior_count, sight_count);
  }
  if (!any_constant && centre_prior_count < 3) {
    uint32_t g1 = config.gauge_image1, g2 = config.gauge_image2;
    if (!poses.count(g1) || !poses.count(g2) || g1 == g2) {
      auto it = poses.begin();
      g1 = it->first;
      g2 = std::next(it)->first;
    }
    problem.SetParameterBlockConstant(poses[g1].q.data());
    problem.SetParameterBlockConstant(poses[g1].t.data());
    auto& t2 = poses[g2].t;
    int largest = 0;
    for (int k = 1; k < 3; ++k)
      if (std::abs(t2[k]) > std::abs(t2[largest])) largest = k;
    // Scale: a stiff prior holds the largest coordinate of t2 (the data are exactly scale-invariant, so the prior
    // meets no resistance). A prior rather than a SubsetManifold keeps every translation block 3-dimensional:
    // with poses (3 + 3) and the usual free intrinsics (f, k1, k2) all camera blocks then have size 3 and Ceres
    // uses its compiled <2, 3, 3> Schur eliminator instead of the dynamic-size one (measured: the Schur
    // elimination was the largest share of global BA time).
    gauge_prior = std::make_unique<ScaleGaugePrior>(largest, t2[largest]);
    problem.AddResidualBlock(gauge_prior.get(), nullptr, t2.data());
  }
  for (auto& [cid, params] : intr) {
    std::vector<int> fixed;
    const bool cam_const = config.constant_cameras.count(cid) > 0;
    auto keep = [&](int k, bool refine) {
      if (cam_const || !refine) fixed.push_back(k);
    };
    keep(core::kF, options.refine_focal);
    keep(core::kAspect, options.refine_aspect);
    keep(core::kU0, options.refine_principal_point);
    keep(core::kV0, options.refine_principal_point);
    keep(core::kK1, options.refine_k1);
    keep(core::kK2, options.refine_k2);
    keep(core::kP1, options.refine_tangential);
    keep(core::kP2, options.refine_tangential);
    if (fixed.size() == core::kNumIntrinsics)
      problem.SetParameterBlockConstant(params.data());
    else if (!fixed.empty()) {
      subset_manifolds.emplace_back(new ceres::SubsetManifold(core::kNumIntrinsics, fixed));
      problem.SetManifold(params.data(), subset_manifolds.back().get());
    }
  }

  ceres::Solver::Options sopts;
  const int num_var_images = static_cast<int>(variable.size());
  sopts.linear_solver_type =
      num_var_images <= options.dense_schur_max_images ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (auto& X : pts) ordering->AddElementToGroup(X.data(), 0);
  for (auto& [id, b] : poses) {
    ordering->AddElementToGroup(b.q.data(), 1);
    ordering->AddElementToGroup(b.t.data(), 1);
  }
  for (auto& [cid, params] : intr) ordering->AddElementToGroup(params.data(), 1);
  sopts.linear_solver_ordering = ordering;
  sopts.max_num_iterations = options.max_iterations;
  sopts.function_tolerance = options.function_tolerance;
  sopts.gradient_tolerance = options.gradient_tolerance;
  sopts.parameter_tolerance = options.parameter_tolerance;
  sopts.num_threads = options.num_threads > 0 ? options.num_threads : core::NumThreads();
  sopts.minimizer_progress_to_stdout = false;
  sopts.logging_type = ceres::SILENT;

  // RMS of the raw (un-robustified) reprojection residuals, the gauge prior left out.
  auto rms = [&]() {
    double sum = 0;
    double r[2];
    for (size_t i = 0; i < costs.size(); ++i) {
      costs[i].Evaluate(residual_params[i].data(), r, nullptr);
      sum += r[0] * r[0] + r[1] * r[1];
    }
    return costs.empty() ? 0.0 : std::sqrt(sum / costs.size());
  };
  const auto t_setup = std::chrono::steady_clock::now();
  out.initial_rms_px = rms();
  ceres::Solver::Summary summary;
  ceres::Solve(sopts, &problem, &summary);
  out.final_rms_px = rms();
  spdlog::debug(
      "BA: {} var images, {} points, {} residuals, {} iterations; setup {:.3f} s, solve {:.3f} s "
      "(pre {:.3f}, jac {:.3f}, res {:.3f}, lin {:.3f}), rms {:.3f} s",
      variable.size(), point_ids.size(), residual_obs.size(), summary.iterations.size(),
      std::chrono::duration<double>(t_setup - start).count(), summary.total_time_in_seconds,
      summary.preprocessor_time_in_seconds, summary.jacobian_evaluation_time_in_seconds,
      summary.residual_evaluation_time_in_seconds, summary.linear_solver_time_in_seconds,
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_setup).count() -
          summary.total_time_in_seconds);
  out.num_residuals = static_cast<int>(residual_obs.size());
  out.num_iterations = static_cast<int>(summary.iterations.size());
  out.success = summary.IsSolutionUsable();
  {
    std::vector<double*> blocks;
    problem.GetParameterBlocks(&blocks);
    for (double* b : blocks)
      if (!problem.IsParameterBlockConstant(b)) out.num_parameters += problem.ParameterBlockTangentSize(b);
  }
  if (out.success && options.compute_intrinsics_covariance) {
    ceres::Covariance::Options co;
    co.num_threads = sopts.num_threads;
    co.apply_loss_function = true;
    ceres::Covariance covariance(co);
    std::vector<std::pair<const double*, const double*>> blocks;
    for (auto& [cid, params] : intr)
      if (!problem.IsParameterBlockConstant(params.data())) blocks.emplace_back(params.data(), params.data());
    const double dof = std::max(1.0, 2.0 * residual_obs.size() - out.num_parameters);
    const double sigma2 = out.final_rms_px * out.final_rms_px * residual_obs.size() / dof;  // SSE / dof
    if (!blocks.empty() && covariance.Compute(blocks, &problem)) {
      for (auto& [cid, params] : intr) {
        if (problem.IsParameterBlockConstant(params.data())) continue;
        Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics, Eigen::RowMajor> m;
        if (covariance.GetCovarianceBlock(params.data(), params.data(), m.data()))
          out.intrinsics_covariance[cid] = sigma2 * m;
      }
    }
  }
  if (out.success) {
    for (auto& [id, b] : poses) {
      if (!variable.count(id) || config.constant_images.count(id)) continue;
      auto& pose = rec->images.at(id).pose;
      pose.q = Eigen::Quaterniond(b.q[3], b.q[0], b.q[1], b.q[2]).normalized();
      pose.t = Eigen::Vector3d(b.t[0], b.t[1], b.t[2]);
    }
    for (auto& [cid, params] : intr) rec->cameras.at(cid).SetParams(params.data());
    for (size_t i = 0; i < point_ids.size(); ++i)
      rec->points.at(point_ids[i]).xyz = Eigen::Vector3d(pts[i][0], pts[i][1], pts[i][2]);
    for (uint64_t pid : point_ids) {
      auto& P = rec->points.at(pid);
      double sum = 0;
      for (const auto& el : P.track) sum += ObservationError(*rec, el.image_id, el.point2d_idx, P.xyz);
      P.error = P.track.empty() ? 0 : sum / P.track.size();
    }
  } else {
    spdlog::warn("bundle adjustment did not converge: {}", summary.BriefReport());
  }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace fmv3d::sfm
