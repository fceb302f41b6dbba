// Synthetic correspondences with exact ground truth, for tests and benchmarks of the mapper without images:
// random 3D points seen by known cameras, projected through a known camera model (with distortion), with
// Gaussian keypoint noise, unmatched clutter keypoints and wrong matches mixed into the verified pairs.
#pragma once

#include <cstdint>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/sfm/incremental_mapper.h"

namespace fmv3d::sfm {

struct SyntheticSceneOptions {
  enum class Layout { kOrbit, kNadirGrid };
  Layout layout = Layout::kOrbit;
  int num_cameras = 40;
  int num_points = 2000;
  int width = 1280, height = 720;
  double focal = 1000;  // true focal (pixels)
  double k1 = -0.08, k2 = 0;
  double u0_offset = 0, v0_offset = 0;  // true principal point minus the image centre
  double aspect = 1;                    // true pixel aspect s_u (fx = focal · aspect)
  double noise_px = 0.5;
  double outlier_ratio = 0.1;       // fraction of each pair's matches replaced by wrong ones
  double clutter_ratio = 0.1;       // extra unmatched keypoints per image
  double guess_focal_factor = 1.2;  // prior focal = factor · max(w, h); ≤ 0: prior = true focal, known
  int min_pair_matches = 30;        // pairs sharing fewer points are not reported
  // Orbit: cameras on an arc of this radius and height around the scene (a disc of radius 3, height ±1.5),
  // looking at its centre. A large radius with a long focal gives telephoto (near-affine) views.
  double orbit_radius = 10, orbit_height = 3, orbit_arc_deg = 360;
  int max_pair_gap = 0;  // > 0: only pairs (i, j) with |i − j| ≤ gap (sequential matching)
  uint64_t seed = 1;
};

struct SyntheticScene {
  core::Reconstruction truth;  // true cameras/poses (images named like input.images), points with tracks
  MapperInput input;           // what the mapper sees
};

SyntheticScene MakeSyntheticScene(const SyntheticSceneOptions& options);

// The true model (cameras, poses, points) with the noisy keypoints of every point as its tracks, no outliers:
// what a perfect mapper would build from MakeSyntheticScene(options), for tests of BA and self-calibration.
core::Reconstruction TrueModelWithObservations(const SyntheticSceneOptions& options);

}  // namespace fmv3d::sfm
