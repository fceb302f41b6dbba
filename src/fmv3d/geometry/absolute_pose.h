// Absolute pose (PnP): a camera's pose from 2D–3D correspondences, robust to outliers.
//
// Minimal solver: OpenCV's AP3P inside RANSAC on undistorted coordinates (a well-kept building block), then our
// own non-linear refinement of the full camera model (distortion included) with a robust loss on the inliers,
// optionally with the focal length (and k1) free when the intrinsics are only a guess.
// Pixels follow the fmv3d convention (core/camera.h); the conversion to OpenCV's is internal.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"

namespace fmv3d::geometry {

struct AbsolutePoseOptions {
  double max_error_px = 12;  // RANSAC inlier threshold (pixels)
  double confidence = 0.9999;
  int max_iterations = 5000;
  int min_inliers = 15;  // fewer inliers than this is a failure
  double min_inlier_ratio = 0.2;
  bool refine = true;         // non-linear refinement on the inliers
  bool refine_focal = false;  // also refine f (camera is then updated): for a lone camera with a guessed focal
  bool refine_k1 = false;
  void Check() const;
};

struct AbsolutePoseResult {
  bool success = false;
  core::Pose pose;
  core::Camera camera;            // the input camera, with f/k1 refined when asked
  std::vector<char> inlier_mask;  // one per correspondence
  int num_inliers = 0;
  double mean_inlier_error_px = 0;
};

AbsolutePoseResult EstimateAbsolutePose(const std::vector<Eigen::Vector2d>& points2d,
                                        const std::vector<Eigen::Vector3d>& points3d, const core::Camera& camera,
                                        const AbsolutePoseOptions& options);

// Robust (Cauchy) Levenberg–Marquardt refinement of a pose on given correspondences (all treated as inliers,
// the loss handles stragglers). Updates pose (and camera f/k1 when asked). Returns false if Ceres fails.
bool RefineAbsolutePose(const std::vector<Eigen::Vector2d>& points2d, const std::vector<Eigen::Vector3d>& points3d,
                        core::Camera* camera, core::Pose* pose, bool refine_focal = false, bool refine_k1 = false,
                        double loss_scale_px = 1.0);

}  // namespace fmv3d::geometry
