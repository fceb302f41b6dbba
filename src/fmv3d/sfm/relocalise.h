// Relocalisation: images the incremental mapper could not register (no verified pair, or pairs too weak to
// chain) are retried against the grown model before the run ends.
//   1. 2D–3D matching: each candidate's descriptors against one representative descriptor per model point (the
//      medoid of its track's descriptors), Lowe's ratio test; no pairwise verification is needed, so an image
//      whose every pair failed two-view RANSAC still finds the points it sees.
//   2. Absolute pose: P3P RANSAC + robust refinement (geometry/absolute_pose.h); accepted with enough inliers.
//   3. Guided matching: the new image's untriangulated keypoints are matched to those of its registered
//      neighbours (the images sharing most points with it) only along the epipolar segment their poses
//      allow (within the model's depth range), where a weak ratio test suffices; the matches are triangulated
//      (angle and reprojection checks), so the next candidate has more points to find.
//   4. Bundle adjustment of the whole model (intrinsics held), then observations above the error bound are
//      dropped. Rounds repeat while images register.
// Pure function on the model and the feature sets; the sparse stage calls it after the mapper.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"
#include "fmv3d/geometry/absolute_pose.h"

namespace fmv3d::sfm {

struct RelocaliseOptions {
  double ratio = 0.8;  // 2D–3D: nearest / second-nearest descriptor distance
  // 2D–3D matches against all model points carry more outliers than a verified pair: a looser inlier ratio,
  // more inliers required than for the mapper's image-to-image registration.
  geometry::AbsolutePoseOptions pose = [] {
    geometry::AbsolutePoseOptions o;
    o.max_error_px = 8;
    o.min_inliers = 30;
    o.min_inlier_ratio = 0.1;
    o.max_iterations = 10000;
    return o;
  }();
  int guided_neighbours = 6;          // registered images matched by guided search per new image
  double guided_max_epipolar_px = 3;  // distance of a match from the epipolar line
  double guided_ratio = 0.9;          // ratio test among the candidates on the epipolar segment
  double tri_min_angle_deg = 1.5;
  double tri_max_error_px = 4;
  double filter_max_error_px = 4;  // after the adjustment
  int max_rounds = 4;
  int ba_max_iterations = 30;
  void Check() const;
};

struct RelocaliseCandidate {
  uint32_t image_id = 0;
  uint32_t camera_id = 0;
  std::string name;
};

struct RelocaliseStats {
  std::vector<uint32_t> registered;              // candidates now in the model, in registration order
  std::map<uint32_t, std::string> still_failed;  // candidate → why it still does not register
  int observations_added = 0, points_added = 0, rounds = 0;
  double seconds = 0;
};

// The model's images' point2d indices must be their feature sets' keypoint indices. `features` holds the
// feature set of every model image and every candidate (by image id); `cameras` the prior camera of every
// camera id (used when a candidate's camera is not in the model yet). Deterministic.
RelocaliseStats RelocaliseImages(core::Reconstruction* rec, const std::vector<RelocaliseCandidate>& candidates,
                                 const std::map<uint32_t, const features::FeatureSet*>& features,
                                 const std::map<uint32_t, core::Camera>& cameras, const RelocaliseOptions& options);

// Guided matching of one registered image pair: for each untriangulated keypoint of image1, the
// untriangulated keypoints of image2 within max_epipolar_px of its epipolar line, between the projections of
// its ray at depths [depth_min, depth_max]; the best by descriptor distance is kept when it passes the ratio
// test against the second best. Returns (keypoint in image1, keypoint in image2) pairs.
std::vector<features::FeatureMatch> GuidedMatches(const core::Reconstruction& rec, uint32_t image1, uint32_t image2,
                                                  const features::FeatureSet& features1,
                                                  const features::FeatureSet& features2, double depth_min,
                                                  double depth_max, double max_epipolar_px, double ratio);

}  // namespace fmv3d::sfm
