// Bundle adjustment with Ceres: camera poses, 3D points and per-camera intrinsics (f, u0, v0, k1, k2; p1, p2
// optional; aspect fixed by default) minimise the robust reprojection error of every observation, using the
// same core::ProjectPoint as the rest of the system (geometry/reprojection_error.h).
//
// Solver: Schur complement (points eliminated first) — DENSE_SCHUR for small problems, SPARSE_SCHUR for large
// ones; Levenberg–Marquardt until the relative cost decrease falls below function_tolerance.
// Gauge: when no constant pose takes part, the first gauge image's pose is held fixed and one translation
// coordinate of the second (its largest) too, which removes rotation, translation and scale freedom.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <set>
#include <vector>

#include "fmv3d/core/reconstruction.h"

namespace fmv3d::sfm {

struct BundleAdjustmentOptions {
  enum class Loss { kTrivial, kHuber, kCauchy };
  Loss loss = Loss::kCauchy;
  double loss_scale_px = 1.0;
  bool refine_focal = true;
  bool refine_principal_point = false;
  bool refine_k1 = true;
  bool refine_k2 = true;
  bool refine_tangential = false;
  bool refine_aspect = false;
  bool refine_points = true;
  int max_iterations = 100;
  double function_tolerance = 1e-6;
  double gradient_tolerance = 1e-10;
  double parameter_tolerance = 1e-8;
  // Levenberg–Marquardt's damping starts at diag(JᵀJ) / this (Ceres' default 1e4). A fit that starts at a
  // neighbouring optimum (a nested-model test) needs a larger one: along a direction that is nearly a gauge
  // freedom (a principal point against a common tilt) the damped first step gains less than function_tolerance,
  // and Ceres then stops without taking it.
  double initial_trust_region_radius = 1e4;
  // Larger problems use SPARSE_SCHUR. Both spend their time forming the reduced camera system (the Schur
  // elimination), where the dense matrix's direct cell access beats the sparse one's look-ups and locks; the
  // dense factorisation (6n + 3 unknowns, n³ flops) only costs as much past a few hundred images. Measured on a
  // 61-image 960x540 video model (424k residuals): dense 4.7 CPU-s vs sparse 6.2 for 6 iterations.
  int dense_schur_max_images = 200;
  // Ceres' threaded evaluation and Schur elimination sum in an order that changes from run to run, so the model
  // would differ in its last digits between two runs and every later stage with it. One thread keeps a resumed
  // or repeated run bit-for-bit equal to the first; 0 uses core::NumThreads() where speed matters more.
  int num_threads = 1;
  // After solving: the posterior covariance of each camera's free intrinsics (points eliminated, poses
  // marginalised: intrinsics_covariance.h), scaled by the residual variance σ² = SSE / (residuals − parameters).
  bool compute_intrinsics_covariance = false;
  void Check() const;
};

// Which part of the model to adjust. Empty variable_images means all images.
struct BundleAdjustmentConfig {
  std::set<uint32_t> variable_images;           // images whose poses move (local BA: the new image and its neighbours)
  std::set<uint32_t> constant_images;           // images whose poses stay fixed even if in variable_images
  std::set<uint32_t> constant_cameras;          // cameras whose intrinsics stay fixed whatever the options say
  uint32_t gauge_image1 = 0, gauge_image2 = 0;  // 0: choose the two lowest image ids
  // Soft priors on camera centres in the model's frame (e.g. telemetry positions in local metres): residual
  // (C − prior) / centre_prior_sigma per axis, Huber loss beyond centre_prior_huber σ. With priors on at least
  // three variable images no gauge is fixed: the priors anchor translation and scale (and rotation unless
  // their positions are collinear; the roll about a straight line then stays where it started).
  std::map<uint32_t, Eigen::Vector3d> centre_priors;
  double centre_prior_sigma = 3.0;
  double centre_prior_huber = 3.0;
  // Soft priors on the optical axes (unit, model frame; e.g. a telemetry line of sight): residual
  // (Rᵀ·z − axis) / axis_prior_sigma_rad. They hold the rotation that collinear centre priors leave free.
  std::map<uint32_t, Eigen::Vector3d> axis_priors;
  double axis_prior_sigma_rad = 0.0175;
  // Soft priors on where the optical axis meets the ground (a telemetry frame centre F at slant range r): residual
  // (C + r·Rᵀ·z − F) / sight_prior_sigma per axis, Huber loss beyond 3σ. They tie both the centre and the
  // pointing; like centre priors they anchor the gauge (three or more).
  std::map<uint32_t, std::pair<Eigen::Vector3d, double>> sight_priors;
  double sight_prior_sigma = 1.0;
  // Observations weighted above the others (the operator's tie points, appended after the automatic keypoints:
  // features/manual_matches.h): in image id, the keypoints with index ≥ weighted_from[id] count
  // observation_weight times (their robust loss scaled by it).
  std::map<uint32_t, uint32_t> weighted_from;
  double observation_weight = 1;
  // Soft priors on 3D points (e.g. ground control points at their surveyed coordinates, the model in local
  // metres): residual (X − prior) / point_prior_sigma per axis. The observations of these points use a Huber loss
  // at point_prior_loss_px instead of the shared robust loss: they are clicked by hand (σ ≈ 1 px), and a Cauchy
  // at the automatic keypoints' scale would discount their honest 2–3 px errors. Priors on three or more points
  // of the adjusted set (not collinear) anchor the gauge, like centre priors.
  // point_prior_observation_weight scales those observations' loss: (σ of the other observations / σ of these)²
  // weighs hand clicks by their real accuracy, so that they place the model without bending each camera's pose
  // towards its own few noisy clicks.
  std::map<uint64_t, Eigen::Vector3d> point_priors;
  double point_prior_sigma = 0.02;
  // Soft priors on the focal of cameras whose f is free: camera id → (prior f, σ), pixels; residual (f − prior) / σ.
  // A stated focal (EXIF, the sensor database) decides what the images leave free: nadir photos from one height see a
  // focal change and a change of depth, ground height and relief alike, so f drifts where the images barely hold it.
  std::map<uint32_t, std::pair<double, double>> focal_priors;
  double point_prior_loss_px = 3;
  double point_prior_observation_weight = 1;
};

struct BundleAdjustmentSummary {
  bool success = false;
  int num_residuals = 0;
  int num_iterations = 0;
  double initial_rms_px = 0, final_rms_px = 0;  // of the raw (un-robustified) residuals
  double seconds = 0;
  int num_parameters = 0;  // free parameters (tangent space)
  // With compute_intrinsics_covariance: camera id → covariance in core::IntrinsicIndex order (rows and columns
  // of held intrinsics are zero). Missing when the system is rank-deficient.
  std::map<uint32_t, Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics>> intrinsics_covariance;
};

// Adjusts rec in place. Points observed by a variable image are variable (with all their observations in the
// problem; images outside the variable set contribute as constants). Point errors are updated afterwards.
BundleAdjustmentSummary BundleAdjust(core::Reconstruction* rec, const BundleAdjustmentConfig& config,
                                     const BundleAdjustmentOptions& options);

// The posterior covariance of each camera's free intrinsics at the model's current values, without adjusting it:
// what compute_intrinsics_covariance gives after BundleAdjust (the same at a converged model), and the bound the
// data allow when the model is the truth. rms and parameter counts are the current values'; no covariance when
// the system is rank-deficient.
BundleAdjustmentSummary IntrinsicsCovarianceAt(const core::Reconstruction& rec, const BundleAdjustmentConfig& config,
                                               const BundleAdjustmentOptions& options);

// Recomputes Point3D::error (mean reprojection error over the track) for all points.
void UpdatePointErrors(core::Reconstruction* rec);

// Reprojection error (pixels) of one observation; infinity when the point is behind the camera.
double ObservationError(const core::Reconstruction& rec, uint32_t image_id, uint32_t point2d_idx,
                        const Eigen::Vector3d& xyz);

}  // namespace fmv3d::sfm
