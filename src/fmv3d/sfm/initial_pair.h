// The initial pair of an incremental model: a candidate pair's relative pose (5-point E on its verified
// matches, normalised with the focal guess), its share of homography inliers and the median triangulation angle
// of its well-reprojected points, from which the mapper picks the pair to start from.
#pragma once

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/features/types.h"
#include "fmv3d/sfm/incremental_mapper.h"

namespace fmv3d::sfm {

struct InitialPairCandidate {
  const features::VerifiedPair* pair = nullptr;
  bool evaluated = false, valid = false;
  double h_ratio = 0;  // homography inliers / verified matches: near 1 for a planar scene or a pure rotation
  double median_angle_deg = 0;
  int num_good = 0;        // matches triangulated in front of both cameras within tri_max_error_px
  double focal_scale = 1;  // chosen multiple of the guessed focal (1 when the focal is known)
  core::Pose pose2;        // pose of image 2 with image 1 at the origin, unit baseline
};

// Evaluates c->pair between images im1 and im2 seen by cameras cam1 and cam2 (their focals scaled by
// focal_scale); valid when at least 8 matches triangulate well. Uses options' tri_max_error_px and
// init_min_inliers.
void EvaluateInitialPair(const MapperImage& im1, const MapperImage& im2, core::Camera cam1, core::Camera cam2,
                         double focal_scale, const MapperOptions& options, InitialPairCandidate* c);

}  // namespace fmv3d::sfm
