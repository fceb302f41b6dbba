// Two-view geometry: fundamental matrix (normalised 8-point + Sampson refinement), essential matrix (5-point in
// RANSAC + relative-pose refinement), homography, and the verification of an image pair that classifies it as
// calibrated / uncalibrated / planar-or-rotation.
//
// Conventions: pixel coordinates in fmv3d's convention (pixel centres at +0.5) — F and H map these coordinates
// (x2^T F x1 = 0, x2 ~ H x1). Normalised coordinates are (x, y) = undistorted ray directions x/z, y/z.
// Relative pose: x_cam2 = R * x_cam1 + t, E = [t]x R, |t| = 1.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/core/camera.h"

namespace fmv3d::geometry {

using Points2 = std::vector<Eigen::Vector2d>;

// Squared Sampson distance of a correspondence to the epipolar geometry M (F in pixels or E in normalised
// coordinates): first-order approximation of the squared reprojection distance.
double SampsonErrorSq(const Eigen::Matrix3d& M, const Eigen::Vector2d& x1, const Eigen::Vector2d& x2);

// Hartley-normalised 8-point algorithm on >= 8 correspondences (least squares for more), rank 2 enforced.
// Returns false for fewer than 8 points or a degenerate configuration. F is scaled to unit Frobenius norm.
bool EightPointFundamental(const Points2& x1, const Points2& x2, Eigen::Matrix3d* F);

// Non-linear least squares (our Levenberg–Marquardt, analytic Jacobian) of the sum of squared Sampson errors over the
// given correspondences, on the rank-2 manifold F = U diag(1, s, 0) V^T (U, V rotations; Hartley-normalised inside for
// conditioning). Returns false when the problem is too small or the solver fails; F is then unchanged.
bool RefineFundamental(const Points2& x1, const Points2& x2, Eigen::Matrix3d* F);

// Non-linear refinement of a relative pose (R, t with |t| = 1) minimising squared Sampson errors of
// E = [t]x R on normalised correspondences, each weighted by `focal` so the cost is in pixels².
bool RefineRelativePose(const Points2& n1, const Points2& n2, double focal, Eigen::Matrix3d* R, Eigen::Vector3d* t);

struct TwoViewOptions {
  double max_error_px = 0;  // RANSAC inlier threshold (pixels); 0 = auto: max(1.5, max(w, h) / 2000)
  double confidence = 0.9999;
  int max_iterations = 10000;
  int min_inliers = 15;                // a pair with fewer F (or H) inliers is rejected
  double min_E_F_inlier_ratio = 0.95;  // E explains ≥ this share of the F inliers → calibrated
  double max_H_inlier_ratio = 0.8;     // H explains > this share of the F inliers → planar or pure rotation
  bool refine = true;                  // non-linear refinement of F and of the relative pose
  uint64_t seed = 0;
  void Check() const;
};

enum class TwoViewClass : uint8_t { kRejected = 0, kCalibrated = 1, kUncalibrated = 2, kPlanarOrRotation = 3 };

struct TwoViewResult {
  TwoViewClass geometry = TwoViewClass::kRejected;
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero(), E = Eigen::Matrix3d::Zero(), H = Eigen::Matrix3d::Zero();
  std::vector<char> inliers_F, inliers_E, inliers_H;  // masks over the input correspondences
  int num_inliers_F = 0, num_inliers_E = 0, num_inliers_H = 0;
  bool has_pose = false;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double median_triangulation_angle_deg = 0;
  // The inlier set of the chosen model (E's for calibrated pairs, else F's): indices into the input.
  std::vector<int> inliers;
};

// Verifies a putative correspondence set between two images. x1, x2 in pixels (fmv3d convention).
// `trust_intrinsics` is false when the cameras' intrinsics are only a guess: the pair's inliers then come from F
// (which does not depend on the guess), while E with the guessed intrinsics is still estimated to decide
// calibrated vs uncalibrated and to give an initial relative pose. Deterministic for a fixed options.seed.
TwoViewResult VerifyTwoView(const Points2& x1, const Points2& x2, const core::Camera& camera1,
                            const core::Camera& camera2, bool trust_intrinsics, const TwoViewOptions& options);

// Angle (radians) of the rotation R_a^T R_b: the distance between two rotations (both orthonormal).
double RotationAngle(const Eigen::Matrix3d& Ra, const Eigen::Matrix3d& Rb);

}  // namespace fmv3d::geometry
