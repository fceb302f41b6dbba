// One file (~510 lines) by design: BundleProblem owns the flat parameter and cost arrays every residual block points
// into, and the order in which it adds them (reprojection, pose priors, point priors, gauge) is what keeps a
// single-threaded solve repeatable; split across files its members would have to share that state through a
// header. The reprojection cost is geometry/reprojection_error.h, the priors ba_priors.h, the covariance
// intrinsics_covariance.cc.
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
#include <utility>

#include "fmv3d/core/error.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/geometry/reprojection_error.h"
#include "fmv3d/sfm/ba_priors.h"
#include "fmv3d/sfm/intrinsics_covariance.h"

namespace fmv3d::sfm {

void BundleAdjustmentOptions::Check() const {
  if (!(loss_scale_px > 0)) throw Error("bundle adjustment: loss_scale_px must be > 0");
  if (max_iterations < 1) throw Error("bundle adjustment: max_iterations must be ≥ 1");
  if (!(function_tolerance > 0)) throw Error("bundle adjustment: function_tolerance must be > 0");
  if (!(initial_trust_region_radius > 0)) throw Error("bundle adjustment: initial_trust_region_radius must be > 0");
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

using ba::AxisPrior;
using ba::CentrePrior;
using ba::FocalPrior;
using ba::PointPrior;
using ba::ScaleGaugePrior;
using ba::SightPrior;

// A pose's parameter blocks, inside BundleProblem's one array of camera parameters.
struct PoseBlock {
  double* q;  // 4, Eigen order x y z w
  double* t;  // 3
};

// Points seen by a variable image (every image observing them takes part), sorted and unique.
std::vector<uint64_t> PointsOfImages(const core::Reconstruction& rec, const std::set<uint32_t>& images) {
  std::vector<uint64_t> point_ids;
  for (uint32_t id : images) {
    auto it = rec.images.find(id);
    if (it == rec.images.end()) continue;
    for (int64_t pid : it->second.point3d_ids)
      if (pid != core::kNoPoint3D) point_ids.push_back(static_cast<uint64_t>(pid));
  }
  std::sort(point_ids.begin(), point_ids.end());
  point_ids.erase(std::unique(point_ids.begin(), point_ids.end()), point_ids.end());
  return point_ids;
}

// One adjustment: the Ceres problem and the parameter and cost blocks it works on, which live in flat arrays
// owned here (the problem does not own them): a global adjustment has hundreds of thousands of residuals, and one
// allocation each (plus Ceres' bookkeeping of owned objects) was a visible share of a short adjustment's time.
// The blocks are declared before the problem, so they outlive it. Residual blocks are added in a fixed order
// (reprojection errors, pose priors, point priors, the gauge), which keeps a single-threaded solve bit-for-bit
// repeatable.
class BundleProblem {
 public:
  BundleProblem(core::Reconstruction* rec, const BundleAdjustmentConfig& config, const BundleAdjustmentOptions& options,
                std::set<uint32_t> variable, std::vector<uint64_t> point_ids)
      : rec_(rec),
        config_(config),
        options_(options),
        variable_(std::move(variable)),
        point_ids_(std::move(point_ids)),
        pts_(point_ids_.size()),
        shared_loss_(MakeLoss(options)),
        problem_(ProblemOptions()) {
    if (!config.weighted_from.empty() && config.observation_weight != 1) {
      if (!(config.observation_weight > 0)) throw Error("bundle adjustment: observation_weight must be positive");
      weighted_loss_ = std::make_unique<ceres::ScaledLoss>(shared_loss_.get(), config.observation_weight,
                                                           ceres::DO_NOT_TAKE_OWNERSHIP);
    }
    if (!config.point_priors.empty()) {
      if (!(config.point_prior_sigma > 0) || !(config.point_prior_loss_px > 0) ||
          !(config.point_prior_observation_weight > 0))
        throw Error("bundle adjustment: point_prior_sigma, _loss_px and _observation_weight must be positive");
      prior_point_loss_ =
          std::make_unique<ceres::ScaledLoss>(new ceres::HuberLoss(config.point_prior_loss_px),
                                              config.point_prior_observation_weight, ceres::TAKE_OWNERSHIP);
    }
    AllocateCameraBlocks();
  }

  void Build() {
    AddReprojectionErrors();
    const bool any_constant = HoldConstantPoses();
    const size_t pose_anchors = AddPosePriors();
    const size_t anchors = std::max(pose_anchors, AddPointPriors());
    if (!any_constant && anchors < 3) FixGauge();
    AddFocalPriors();
    FreeIntrinsics();
  }

  ceres::Solver::Summary Solve() {
    ceres::Solver::Options sopts;
    const int num_var_images = static_cast<int>(variable_.size());
    sopts.linear_solver_type =
        num_var_images <= options_.dense_schur_max_images ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    for (auto& X : pts_) ordering->AddElementToGroup(X.data(), 0);
    for (auto& [id, b] : poses_) {
      ordering->AddElementToGroup(b.q, 1);
      ordering->AddElementToGroup(b.t, 1);
    }
    for (auto& [cid, params] : intr_) ordering->AddElementToGroup(params, 1);
    sopts.linear_solver_ordering = ordering;
    sopts.max_num_iterations = options_.max_iterations;
    sopts.function_tolerance = options_.function_tolerance;
    sopts.gradient_tolerance = options_.gradient_tolerance;
    sopts.parameter_tolerance = options_.parameter_tolerance;
    sopts.initial_trust_region_radius = options_.initial_trust_region_radius;
    sopts.num_threads = NumThreads();
    sopts.minimizer_progress_to_stdout = false;
    sopts.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(sopts, &problem_, &summary);
    return summary;
  }

  // RMS of the raw (un-robustified) reprojection residuals, priors left out. Evaluated directly:
  // ceres::Problem::Evaluate builds a whole program for it (measured ~10% of a local adjustment).
  double Rms() const {
    double sum = 0;
    double r[2];
    for (size_t i = 0; i < costs_.size(); ++i) {
      costs_[i].Evaluate(residual_params_[i].data(), r, nullptr);
      sum += r[0] * r[0] + r[1] * r[1];
    }
    return costs_.empty() ? 0.0 : std::sqrt(sum / costs_.size());
  }

  size_t num_residuals() const { return residual_params_.size(); }
  size_t num_variable_images() const { return variable_.size(); }
  size_t num_points() const { return point_ids_.size(); }

  int NumFreeParameters() const {
    std::vector<double*> blocks;
    problem_.GetParameterBlocks(&blocks);
    int n = 0;
    for (double* b : blocks)
      if (!problem_.IsParameterBlockConstant(b)) n += problem_.ParameterBlockTangentSize(b);
    return n;
  }

  // The posterior covariance of each camera's free intrinsics (points eliminated, poses marginalised:
  // intrinsics_covariance.h), scaled by σ² = SSE / dof. Nothing when the system is rank-deficient.
  void IntrinsicsCovariance(BundleAdjustmentSummary* out) const {
    std::vector<const double*> targets, points;
    std::vector<uint32_t> ids;
    for (const auto& [cid, params] : intr_) {
      if (problem_.IsParameterBlockConstant(params)) continue;
      targets.push_back(params);
      ids.push_back(cid);
    }
    if (targets.empty()) return;
    points.reserve(pts_.size());
    for (const auto& X : pts_) points.push_back(X.data());
    const auto start = std::chrono::steady_clock::now();
    const auto cov = MarginalCovariance(problem_, points, targets);
    spdlog::debug("BA: intrinsics covariance {:.3f} s{}",
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
                  cov ? "" : ", rank-deficient");
    if (!cov) return;
    const double n = static_cast<double>(num_residuals());
    const double dof = std::max(1.0, 2.0 * n - out->num_parameters);
    const double sigma2 = out->final_rms_px * out->final_rms_px * n / dof;  // SSE / dof
    for (size_t i = 0; i < ids.size(); ++i) out->intrinsics_covariance[ids[i]] = sigma2 * (*cov)[i];
  }

  // Copies the adjusted poses, intrinsics and points into the reconstruction and updates the points' errors.
  void WriteBack() {
    for (auto& [id, b] : poses_) {
      if (!IsVariable(id)) continue;
      auto& pose = rec_->images.at(id).pose;
      pose.q = Eigen::Quaterniond(b.q[3], b.q[0], b.q[1], b.q[2]).normalized();
      pose.t = Eigen::Vector3d(b.t[0], b.t[1], b.t[2]);
    }
    for (auto& [cid, params] : intr_) rec_->cameras.at(cid).SetParams(params);
    for (size_t i = 0; i < point_ids_.size(); ++i)
      rec_->points.at(point_ids_[i]).xyz = Eigen::Vector3d(pts_[i][0], pts_[i][1], pts_[i][2]);
    for (uint64_t pid : point_ids_) {
      auto& P = rec_->points.at(pid);
      double sum = 0;
      for (const auto& el : P.track) sum += ObservationError(*rec_, el.image_id, el.point2d_idx, P.xyz);
      P.error = P.track.empty() ? 0 : sum / P.track.size();
    }
  }

 private:
  static std::unique_ptr<ceres::LossFunction> MakeLoss(const BundleAdjustmentOptions& options) {
    switch (options.loss) {
      case BundleAdjustmentOptions::Loss::kCauchy:
        return std::make_unique<ceres::CauchyLoss>(options.loss_scale_px);
      case BundleAdjustmentOptions::Loss::kHuber:
        return std::make_unique<ceres::HuberLoss>(options.loss_scale_px);
      default:
        return nullptr;
    }
  }
  static ceres::Problem::Options ProblemOptions() {
    ceres::Problem::Options popts;
    popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // one shared loss for every residual
    popts.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;  // costs_ and the priors
    popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;       // quaternion_manifold_, subset_manifolds_
    return popts;
  }
  // The operator's tie points (keypoints from weighted_from[image] on) count observation_weight times.
  ceres::LossFunction* LossOf(uint32_t image_id, uint32_t point2d_idx) const {
    if (weighted_loss_) {
      const auto w = config_.weighted_from.find(image_id);
      if (w != config_.weighted_from.end() && point2d_idx >= w->second) return weighted_loss_.get();
    }
    return shared_loss_.get();
  }
  int NumThreads() const { return options_.num_threads > 0 ? options_.num_threads : core::NumThreads(); }
  bool IsVariable(uint32_t id) const { return variable_.count(id) && !config_.constant_images.count(id); }

  // The poses and intrinsics of every image observing the points, in one array ordered by image id, then camera
  // id. Ceres orders the blocks of an elimination group by address, so one array in id order gives the same
  // elimination order, and the same bits, on every run, whatever the heap looked like before.
  void AllocateCameraBlocks() {
    std::set<uint32_t> images, cameras;
    for (uint64_t pid : point_ids_)
      for (const auto& el : rec_->points.at(pid).track) {
        images.insert(el.image_id);
        cameras.insert(rec_->images.at(el.image_id).camera_id);
      }
    camera_blocks_.resize(7 * images.size() + core::kNumIntrinsics * cameras.size());
    double* next = camera_blocks_.data();
    for (uint32_t id : images) {
      const core::Pose& pose = rec_->images.at(id).pose;
      const PoseBlock b{next, next + 4};
      b.q[0] = pose.q.x(), b.q[1] = pose.q.y(), b.q[2] = pose.q.z(), b.q[3] = pose.q.w();
      b.t[0] = pose.t.x(), b.t[1] = pose.t.y(), b.t[2] = pose.t.z();
      poses_.emplace(id, b);
      next += 7;
    }
    for (uint32_t cid : cameras) {
      const auto params = rec_->cameras.at(cid).Params();
      std::copy(params.begin(), params.end(), next);
      intr_.emplace(cid, next);
      next += core::kNumIntrinsics;
    }
  }

  void AddReprojectionErrors() {
    size_t num_obs = 0;
    for (uint64_t pid : point_ids_) num_obs += rec_->points.at(pid).track.size();
    residual_params_.reserve(num_obs);
    for (size_t i = 0; i < point_ids_.size(); ++i) {
      auto& P = rec_->points.at(point_ids_[i]);
      auto& X = pts_[i];
      X = {P.xyz.x(), P.xyz.y(), P.xyz.z()};
      const bool has_prior = config_.point_priors.count(point_ids_[i]) > 0;
      for (const auto& el : P.track) {
        auto& image = rec_->images.at(el.image_id);
        const PoseBlock& pose = poses_.at(el.image_id);
        costs_.emplace_back(image.points2d[el.point2d_idx]);
        residual_params_.push_back({intr_.at(image.camera_id), pose.q, pose.t, X.data()});
        problem_.AddResidualBlock(&costs_.back(),
                                  has_prior ? prior_point_loss_.get() : LossOf(el.image_id, el.point2d_idx),
                                  residual_params_.back().data(), 4);
      }
      if (!options_.refine_points) problem_.SetParameterBlockConstant(X.data());
    }
  }

  // Poses are variable unless constant or outside the variable set. True when any is held.
  bool HoldConstantPoses() {
    bool any_constant = false;
    for (auto& [id, b] : poses_) {
      problem_.SetManifold(b.q, &quaternion_manifold_);
      if (!IsVariable(id)) {
        problem_.SetParameterBlockConstant(b.q);
        problem_.SetParameterBlockConstant(b.t);
        any_constant = true;
      }
    }
    return any_constant;
  }

  // Centre, axis and line-of-sight priors (see the header). Returns how many variable images they anchor: three
  // or more fix the gauge.
  size_t AddPosePriors() {
    size_t anchors = 0;
    if (!config_.centre_priors.empty()) {
      if (!(config_.centre_prior_sigma > 0)) throw Error("bundle adjustment: centre_prior_sigma must be positive");
      prior_loss_ = std::make_unique<ceres::HuberLoss>(config_.centre_prior_huber);
      for (const auto& [id, c] : config_.centre_priors) {
        const auto it = poses_.find(id);
        if (it == poses_.end() || !IsVariable(id)) continue;
        prior_costs_.emplace_back(
            new ceres::AutoDiffCostFunction<CentrePrior, 3, 4, 3>(new CentrePrior(c, config_.centre_prior_sigma)));
        problem_.AddResidualBlock(prior_costs_.back().get(), prior_loss_.get(), it->second.q, it->second.t);
        ++anchors;
      }
    }
    if (!config_.axis_priors.empty()) {
      if (!(config_.axis_prior_sigma_rad > 0)) throw Error("bundle adjustment: axis_prior_sigma_rad must be positive");
      for (const auto& [id, axis] : config_.axis_priors) {
        const auto it = poses_.find(id);
        if (it == poses_.end() || !IsVariable(id)) continue;
        prior_costs_.emplace_back(
            new ceres::AutoDiffCostFunction<AxisPrior, 3, 4>(new AxisPrior(axis, config_.axis_prior_sigma_rad)));
        problem_.AddResidualBlock(prior_costs_.back().get(), nullptr, it->second.q);
      }
    }
    if (!config_.sight_priors.empty()) {
      if (!(config_.sight_prior_sigma > 0)) throw Error("bundle adjustment: sight_prior_sigma must be positive");
      sight_loss_ = std::make_unique<ceres::HuberLoss>(3.0);
      size_t sight_count = 0;
      for (const auto& [id, fr] : config_.sight_priors) {
        const auto it = poses_.find(id);
        if (it == poses_.end() || !IsVariable(id)) continue;
        prior_costs_.emplace_back(new ceres::AutoDiffCostFunction<SightPrior, 3, 4, 3>(
            new SightPrior(fr.first, fr.second, config_.sight_prior_sigma)));
        problem_.AddResidualBlock(prior_costs_.back().get(), sight_loss_.get(), it->second.q, it->second.t);
        ++sight_count;
      }
      if (sight_count >= 3) anchors = std::max(anchors, sight_count);
    }
    return anchors;
  }

  // Focal priors (see the header) on the cameras in the problem.
  void AddFocalPriors() {
    for (const auto& [cid, prior] : config_.focal_priors) {
      const auto it = intr_.find(cid);
      if (it == intr_.end()) continue;
      if (!(prior.second > 0)) throw Error("bundle adjustment: a focal prior's σ must be positive");
      prior_costs_.emplace_back(new FocalPrior(prior.first, prior.second));
      problem_.AddResidualBlock(prior_costs_.back().get(), nullptr, it->second);
    }
  }

  // Point priors (see the header) on the adjusted points. Returns how many: three or more fix the gauge.
  size_t AddPointPriors() {
    size_t anchors = 0;
    for (const auto& [pid, prior] : config_.point_priors) {
      const auto it = std::lower_bound(point_ids_.begin(), point_ids_.end(), pid);
      if (it == point_ids_.end() || *it != pid) continue;
      prior_costs_.emplace_back(
          new ceres::AutoDiffCostFunction<PointPrior, 3, 3>(new PointPrior(prior, config_.point_prior_sigma)));
      problem_.AddResidualBlock(prior_costs_.back().get(), nullptr, pts_[it - point_ids_.begin()].data());
      ++anchors;
    }
    return anchors;
  }

  // Nothing else anchors the model: the first gauge image is held, and a stiff prior holds the largest coordinate
  // of the second's translation (the data are exactly scale-invariant, so the prior meets no resistance). A prior
  // rather than a SubsetManifold keeps every translation block 3-dimensional: with poses (3 + 3) and the usual free
  // intrinsics (f, k1, k2) all camera blocks then have size 3 and Ceres uses its compiled <2, 3, 3> Schur
  // eliminator instead of the dynamic-size one (measured: the Schur elimination was the largest share of global
  // BA time).
  void FixGauge() {
    uint32_t g1 = config_.gauge_image1, g2 = config_.gauge_image2;
    if (!poses_.count(g1) || !poses_.count(g2) || g1 == g2) {
      auto it = poses_.begin();
      g1 = it->first;
      g2 = std::next(it)->first;
    }
    problem_.SetParameterBlockConstant(poses_.at(g1).q);
    problem_.SetParameterBlockConstant(poses_.at(g1).t);
    double* t2 = poses_.at(g2).t;
    int largest = 0;
    for (int k = 1; k < 3; ++k)
      if (std::abs(t2[k]) > std::abs(t2[largest])) largest = k;
    gauge_prior_ = std::make_unique<ScaleGaugePrior>(largest, t2[largest]);
    problem_.AddResidualBlock(gauge_prior_.get(), nullptr, t2);
  }

  // Each camera's intrinsics: the refined subset free, the rest held (all of them for a constant camera).
  void FreeIntrinsics() {
    for (auto& [cid, params] : intr_) {
      std::vector<int> fixed;
      const bool cam_const = config_.constant_cameras.count(cid) > 0;
      auto keep = [&](int k, bool refine) {
        if (cam_const || !refine) fixed.push_back(k);
      };
      keep(core::kF, options_.refine_focal);
      keep(core::kAspect, options_.refine_aspect);
      keep(core::kU0, options_.refine_principal_point);
      keep(core::kV0, options_.refine_principal_point);
      keep(core::kK1, options_.refine_k1);
      keep(core::kK2, options_.refine_k2);
      keep(core::kP1, options_.refine_tangential);
      keep(core::kP2, options_.refine_tangential);
      if (fixed.size() == core::kNumIntrinsics) {
        problem_.SetParameterBlockConstant(params);
      } else if (!fixed.empty()) {
        subset_manifolds_.emplace_back(new ceres::SubsetManifold(core::kNumIntrinsics, fixed));
        problem_.SetManifold(params, subset_manifolds_.back().get());
      }
    }
  }

  core::Reconstruction* rec_;
  const BundleAdjustmentConfig& config_;
  const BundleAdjustmentOptions& options_;
  const std::set<uint32_t> variable_;
  const std::vector<uint64_t> point_ids_;

  std::vector<double> camera_blocks_;  // sized once: the pointers below point into it
  std::map<uint32_t, PoseBlock> poses_;
  std::map<uint32_t, double*> intr_;
  std::vector<std::array<double, 3>> pts_;
  std::deque<geometry::AnalyticReprojectionError> costs_;  // stable addresses, allocated in chunks
  std::vector<std::array<double*, 4>> residual_params_;    // per reprojection residual, for Rms()
  ceres::EigenQuaternionManifold quaternion_manifold_;
  std::unique_ptr<ceres::LossFunction> shared_loss_;    // one object: as many residuals would mean as many allocations
  std::unique_ptr<ceres::LossFunction> weighted_loss_;  // shared_loss_ scaled, for weighted observations
  std::vector<std::unique_ptr<ceres::Manifold>> subset_manifolds_;
  std::unique_ptr<ceres::CostFunction> gauge_prior_;
  std::vector<std::unique_ptr<ceres::CostFunction>> prior_costs_;
  std::unique_ptr<ceres::LossFunction> prior_loss_, sight_loss_, prior_point_loss_;
  ceres::Problem problem_;
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
  std::vector<uint64_t> point_ids = PointsOfImages(*rec, variable);
  if (point_ids.empty()) return out;

  BundleProblem problem(rec, config, options, std::move(variable), std::move(point_ids));
  problem.Build();
  const auto t_setup = std::chrono::steady_clock::now();
  out.initial_rms_px = problem.Rms();
  const ceres::Solver::Summary summary = problem.Solve();
  out.final_rms_px = problem.Rms();
  spdlog::debug(
      "BA: {} var images, {} points, {} residuals, {} iterations; setup {:.3f} s, solve {:.3f} s "
      "(pre {:.3f}, jac {:.3f}, res {:.3f}, lin {:.3f}), rms {:.3f} s",
      problem.num_variable_images(), problem.num_points(), problem.num_residuals(), summary.iterations.size(),
      std::chrono::duration<double>(t_setup - start).count(), summary.total_time_in_seconds,
      summary.preprocessor_time_in_seconds, summary.jacobian_evaluation_time_in_seconds,
      summary.residual_evaluation_time_in_seconds, summary.linear_solver_time_in_seconds,
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_setup).count() -
          summary.total_time_in_seconds);
  out.num_residuals = static_cast<int>(problem.num_residuals());
  out.num_iterations = static_cast<int>(summary.iterations.size());
  out.success = summary.IsSolutionUsable();
  out.num_parameters = problem.NumFreeParameters();
  if (out.success && options.compute_intrinsics_covariance) problem.IntrinsicsCovariance(&out);
  if (out.success)
    problem.WriteBack();
  else
    spdlog::warn("bundle adjustment did not converge: {}", summary.BriefReport());
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

BundleAdjustmentSummary IntrinsicsCovarianceAt(const core::Reconstruction& rec, const BundleAdjustmentConfig& config,
                                               const BundleAdjustmentOptions& options) {
  options.Check();
  BundleAdjustmentSummary out;
  if (rec.images.size() < 2) return out;
  std::set<uint32_t> variable = config.variable_images;
  if (variable.empty())
    for (const auto& [id, im] : rec.images) variable.insert(id);
  std::vector<uint64_t> point_ids = PointsOfImages(rec, variable);
  if (point_ids.empty()) return out;
  // The problem reads the model only (WriteBack, the one writer, is not called).
  BundleProblem problem(const_cast<core::Reconstruction*>(&rec), config, options, std::move(variable),
                        std::move(point_ids));
  problem.Build();
  out.initial_rms_px = out.final_rms_px = problem.Rms();
  out.num_residuals = static_cast<int>(problem.num_residuals());
  out.num_parameters = problem.NumFreeParameters();
  out.success = true;
  problem.IntrinsicsCovariance(&out);
  return out;
}

}  // namespace fmv3d::sfm
