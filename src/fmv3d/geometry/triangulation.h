// Multi-view triangulation of one 3D point from calibrated observations.
//
// Observations are given as world-to-camera poses and *normalised* image coordinates (distortion removed,
// x = X/Z, y = Y/Z in the camera frame), so the same code serves every camera model. Checks in pixels are the
// caller's job (sfm/ knows the cameras); this file offers the geometric checks that need no intrinsics.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "fmv3d/core/pose.h"

namespace fmv3d::geometry {

// Linear (DLT) triangulation: minimises the algebraic error of x_i × (P_i X) = 0 over all views with an SVD of
// the stacked 2N x 4 system. Returns false when fewer than two views are given or the solution is at infinity.
bool TriangulateDLT(const std::vector<core::Pose>& poses, const std::vector<Eigen::Vector2d>& normalized,
                    Eigen::Vector3d* point);

// Refines a point by Gauss–Newton on the angular/normalised reprojection error (a few iterations; cheap).
// Keeps the input when an iteration does not decrease the error.
void RefinePoint(const std::vector<core::Pose>& poses, const std::vector<Eigen::Vector2d>& normalized,
                 Eigen::Vector3d* point, int iterations = 5);

// Angle (radians) between the rays from two camera centres to a point.
double TriangulationAngle(const Eigen::Vector3d& centre1, const Eigen::Vector3d& centre2, const Eigen::Vector3d& point);

// Largest pairwise ray angle (radians) over the given centres (O(N²), N is a track length).
double MaxTriangulationAngle(const std::vector<Eigen::Vector3d>& centres, const Eigen::Vector3d& point);

// True when the point lies in front of the camera (positive depth).
inline bool HasPositiveDepth(const core::Pose& pose, const Eigen::Vector3d& point) {
  return pose.Transform(point).z() > 1e-12;
}

}  // namespace fmv3d::geometry
