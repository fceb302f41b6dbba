// Self-calibration by nested-model tests: is an intrinsic parameter group (focal, principal point, aspect,
// tangential distortion) worth freeing in the final bundle adjustment? The model with the group held (the null
// model) is nested in the one with it free; both are fitted to the same observations (the Gaussian core, below)
// with plain squared errors. Two questions decide, each answered from the data:
//
//  1. Does freeing it explain the observations better than pure noise would? The drop of the squared error in
//     units of the noise variance, Δχ² = (SSE₀ − SSE₁) / σ² with σ² = SSE₀ / dof, is compared with the Bayesian
//     information criterion's price of k extra parameters, k · ln(n) for n residuals (free when BIC₁ < BIC₀).
//     A fixed Δχ² threshold instead (min_delta_chi2 > 0) is available for callers that need one.
//     Δχ² is a χ² only for Gaussian errors, and reprojection errors are heavy-tailed: features on occlusion
//     contours and near-repeats inside the filter's tolerance (on a 30-frame synthetic orbit 15% of the
//     observations lie beyond 3.4σ of the core and make 82% of the squared error). Such errors move with the
//     viewpoint, so they are not noise: they pull a weakly determined parameter (there a centred principal point
//     went 8.5 px off, trading against a common tilt, with the focal 0.9% short) while inflating σ², and the
//     pull passed for signal. Both fits therefore use only the observations inside the Gaussian core of the null
//     model's fit: within the bound a χ²(2) exceeds with probability 1 − core_mass, σ from the median error.
//  2. Do the data determine it? The posterior covariance of the freed parameters (the BA's covariance)
//     gives each one's standard deviation σ_θ. Holding a group costs the squared shift ΣΔθ² the data ask for
//     (its bias), freeing it costs Σσ_θ² (its variance): the group must move by more than its uncertainty. One
//     the data leave uncertain (a principal point trading against a common tilt of the cameras, a focal on a
//     telephoto plateau) would only move the cameras by its uncertainty: it stays held. The 1σ displacement at
//     the image corner is reported beside it.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::sfm {

// k2 and k1 are refined through growth (a guessed lens may be strongly distorted); their final tests ask whether
// the data need them at all, against the prior's values (0 for photos that were undistorted).
enum class IntrinsicGroup { kFocal, kPrincipalPoint, kAspect, kTangential, kK1, kK2 };

const char* ToString(IntrinsicGroup group);
// "f", "aspect", "u0", "v0", "k1", "k2", "p1", "p2".
const char* IntrinsicName(core::IntrinsicIndex parameter);
// The parameters the group frees (per camera), in core::IntrinsicIndex.
std::vector<core::IntrinsicIndex> Parameters(IntrinsicGroup group);
// Sets the refine flag(s) of the group in options.
void SetRefine(IntrinsicGroup group, bool refine, BundleAdjustmentOptions* options);
// Pixels a unit change of the parameter moves the projection of a point at the image corner (the largest
// effect in the image), for the camera given.
double CornerDisplacementPerUnit(const core::Camera& camera, core::IntrinsicIndex parameter);

struct NestedModelTestOptions {
  double min_delta_chi2 = 0;  // > 0: free when Δχ² exceeds this (question 1 by a fixed threshold)
  // Both fits use the observations within the χ²(2) bound holding this mass of Gaussian errors (0.9973: the
  // two-dimensional 3σ); 1 keeps every observation.
  double core_mass = 0.9973;
  bool require_determined = true;  // question 2 (needs the covariance; skipped when false)
};

enum class NestedModelDecision {
  kFreed,           // both questions answered yes
  kNotSignificant,  // Δχ² below the price of the extra parameters
  kUndetermined,    // significant, but a parameter's posterior σ exceeds the shift the data ask for
  kFailed,          // a fit failed or the covariance could not be computed (rank-deficient): held
};
const char* ToString(NestedModelDecision decision);

struct NestedModelTestResult {
  IntrinsicGroup group = IntrinsicGroup::kFocal;
  NestedModelDecision decision = NestedModelDecision::kFailed;
  int num_observations = 0;
  int num_parameters = 0;  // extra parameters freed
  double dof = 0;          // 2 · observations − pose and point parameters
  double delta_chi2 = 0;
  double threshold = 0;                      // Δχ² needed: k · ln(2 · observations), or the fixed threshold
  bool fixed_threshold = false;              // threshold is NestedModelTestOptions::min_delta_chi2, not BIC's
  double rms_held_px = 0, rms_freed_px = 0;  // over the Gaussian core
  int observations_left_out = 0;             // outside the core (NestedModelTestOptions::core_mass)
  double core_sigma_px = 0;                  // the core's σ per axis, from the median error
  std::vector<core::IntrinsicIndex> parameters;
  std::vector<double> held_values, freed_values, sigmas;  // per parameter; sigmas empty without covariance
  double max_sigma_px = 0;                                // the largest 1σ corner displacement of a freed parameter
  core::Camera held, freed;                               // the first camera of each fit
  bool freed_decision() const { return decision == NestedModelDecision::kFreed; }
};

// Fits the model with the group held (options as given, group forced off) and then freed from the held optimum,
// with a plain squared loss, on the Gaussian core of the observations. On kFreed *rec takes the freed fit's
// intrinsics (its poses and points are the caller's to adjust); otherwise it is left unchanged. options: the
// intrinsics refined in both models, iteration budget and tolerance.
NestedModelTestResult TestNestedModel(core::Reconstruction* rec, const BundleAdjustmentConfig& config,
                                      BundleAdjustmentOptions options, IntrinsicGroup group,
                                      const NestedModelTestOptions& test_options);

// The posterior uncertainty of a camera's free intrinsics in the final model (the BA covariance at the final
// adjustment's optimum), stated for the operator whatever the tests decided. A parameter is weakly determined when
// its 1σ moves the projection at the image corner by more than weak_corner_px: the cameras built on it are then
// uncertain at the pixel level (an orbit at one altitude and depression over flat ground leaves the focal and v0
// one weakly determined combination: bench/results/pp11.md).
struct IntrinsicUncertainty {
  core::IntrinsicIndex parameter = core::kF;
  double value = 0, sigma = 0;
  double corner_sigma_px = 0;  // σ · CornerDisplacementPerUnit
  bool weak = false;
};

struct IntrinsicsPosterior {
  uint32_t camera_id = 0;
  double weak_corner_px = 1;
  // False: the covariance is rank-deficient (some combination of the free parameters is not determined at all);
  // parameters then carry their values only.
  bool determined = false;
  std::vector<IntrinsicUncertainty> parameters;  // the free ones, in core::IntrinsicIndex order
  Eigen::MatrixXd correlation;                   // between them (determined only)
  // The least determined combination: the largest eigenvalue of the covariance in corner pixels (each parameter
  // scaled by its corner displacement per unit), its 1σ and unit direction (per parameter, in that scaling).
  double weakest_corner_sigma_px = 0;
  std::vector<double> weakest_direction;
  bool any_weak() const {
    return !determined || std::any_of(parameters.begin(), parameters.end(), [](const auto& p) { return p.weak; });
  }
};

// The intrinsics options frees, in core::IntrinsicIndex order.
std::vector<core::IntrinsicIndex> FreeIntrinsics(const BundleAdjustmentOptions& options);

// Describes the posterior of camera's free parameters from the BA covariance (nullptr: rank-deficient).
IntrinsicsPosterior DescribePosterior(const core::Camera& camera, const std::vector<core::IntrinsicIndex>& free,
                                      const Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics>* cov,
                                      double weak_corner_px);

}  // namespace fmv3d::sfm
