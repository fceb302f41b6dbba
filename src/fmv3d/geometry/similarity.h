// Similarity (Sim3) estimation between point sets, dst ≈ s·R·src + t: the one module every stage uses (evaluation
// against ground truth, ICP and track alignment, georeferencing).
//   - least squares: weighted Umeyama (1991), optionally rigid (s = 1);
//   - along a line: for a collinear source (a straight flight), direction, scale and centroid only;
//   - with the rotation held: scale and translation with their covariance;
//   - robust: RANSAC with an inlier bound, or least median of squares (LMedS) with no bound to guess, both over
//     minimal 3-point samples (geometry/robust.h).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/core/pose.h"

namespace fmv3d::geometry {

// Weighted least-squares similarity (rigid when !estimate_scale). weights: empty (all 1) or one per pair, ≥ 0.
// Returns false for fewer than 3 pairs, mismatched sizes, or a degenerate (collinear) source.
bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        const std::vector<double>& weights, bool estimate_scale, core::Sim3* sim);
// Unweighted, with scale.
bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        core::Sim3* sim);

// Similarity of two point sets along a line (the source collinear or nearly so): the principal directions, the
// scale along them and the centroids are fitted; the rotation about the line is the minimal one taking the
// source direction to the destination's (the caller fixes that roll). False when the sets have no spread or
// their projections on the lines are uncorrelated.
bool EstimateSimilarityAlongLine(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                                 core::Sim3* sim);

// √(λ₂/λ₁) of the points' scatter matrix (second over first principal spread): 0 on a line, 1 isotropic in a plane.
double Collinearity(const std::vector<Eigen::Vector3d>& points);

// Scale and translation of a similarity whose rotation R is held, with their 4×4 covariance (s, tx, ty, tz) up
// to the residuals' variance (the inverse normal matrix for weights 1/σ²).
struct ScaleShift {
  double scale = 1;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
};
// Weighted least squares of (s, t) in dst ≈ s·R·src + t. Requires ≥ 2 pairs with distinct src and a positive
// scale; returns false otherwise.
bool EstimateScaleShift(const Eigen::Matrix3d& R, const std::vector<Eigen::Vector3d>& src,
                        const std::vector<Eigen::Vector3d>& dst, const std::vector<double>& weights, ScaleShift* out);

struct SimilarityRansacOptions {
  double max_error = 0;  // inlier distance in dst units; must be > 0
  int max_iterations = 1000;
  uint64_t seed = 42;
  void Check() const;
};

// RANSAC over minimal 3-point samples, then a least-squares fit on the inliers (twice). Returns the number of
// inliers (0 on failure); inlier_mask (optional) gets one flag per pair.
int EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                             const SimilarityRansacOptions& options, core::Sim3* sim,
                             std::vector<char>* inlier_mask = nullptr);

struct SimilarityLMedSOptions {
  int max_samples = 2000;              // random minimal samples (every triple up to 14 pairs)
  double min_inlier_threshold = 0.05;  // floor of the 3.5σ inlier bound, dst units (noise-free data)
  uint64_t seed = 42;
  void Check() const;
};
struct SimilarityLMedS {
  core::Sim3 sim;
  std::vector<char> inliers;  // one per pair: within the final bound
  double sigma = 0;           // per-axis residual σ of the inliers (7 dof fitted)
  bool along_line = false;    // the source is collinear: fitted along the line, the roll about it left free
};
// Least median of squares over minimal samples, then: σ from the median 3D residual (the median of a 3-dof χ is
// 1.538σ, with Rousseeuw & Leroy's small-sample factor 1 + 5/(n−3)), inliers within max(floor, 3.5σ) (≈ the 99%
// quantile of the 3D norm), a least-squares refit on them and σ from their residuals, three rounds. A collinear
// source (Collinearity < 1e-3) is fitted along its line. Throws fmv3d::Error with fewer than 3 pairs or when no
// sample gives a similarity.
SimilarityLMedS EstimateSimilarityLMedS(const std::vector<Eigen::Vector3d>& src,
                                        const std::vector<Eigen::Vector3d>& dst, const SimilarityLMedSOptions& options);

}  // namespace fmv3d::geometry
