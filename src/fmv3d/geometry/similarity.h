// Similarity (Sim3) estimation between two point sets: Umeyama's closed form, and a RANSAC wrapper for sets
// with outliers. Used to align models to ground truth (evaluation) and to each other.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/core/pose.h"

namespace fmv3d::geometry {

// Least-squares similarity dst ≈ s·R·src + t (Umeyama 1991). Needs ≥ 3 non-collinear pairs; returns false
// otherwise (or when the sizes differ).
bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        core::Sim3* sim);

struct SimilarityRansacOptions {
  double max_error = 0;  // inlier distance in dst units; must be > 0
  int max_iterations = 1000;
  uint64_t seed = 42;
  void Check() const;
};

// RANSAC over minimal 3-point samples, then a least-squares fit on the inliers. Returns the number of inliers
// (0 on failure); inlier_mask (optional) gets one flag per pair.
int EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                             const SimilarityRansacOptions& options, core::Sim3* sim,
                             std::vector<char>* inlier_mask = nullptr);

}  // namespace fmv3d::geometry
