// Global registration: a similarity from nothing, good enough for ScaledIcp to finish (icp.h).
//
// What it assumes: the two sets show roughly the same part of the world (their RMS radii give the scale
// guess). Partial overlap with very different extents (a CAD model of one building against a reconstruction
// of the whole block) needs a user-given start instead (e.g. `fmv3d compare --transform`).
//
// How. Both sets are voxel-thinned to ~max_points points, the source scaled by the radius ratio. Candidates:
//   - principal axes: the 24 proper rotations that map the source's PCA axes onto the target's (every
//     permutation and sign — the axis order is unreliable when two extents are similar), centroids matched;
//   - FPFH features (Rusu et al. 2009; computed with Open3D) matched mutually in feature space, then our
//     seeded RANSAC + Umeyama similarity (geometry/similarity.h) on those 3D pairs — deterministic.
// Every candidate is scored by the share of source points within 4 voxels of the target; the best few are
// refined by a short rigid point-to-plane ICP and scored again at 2 voxels; the best wins.
#pragma once

#include <cstdint>
#include <string>

#include "fmv3d/align/icp.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::align {

struct GlobalRegistrationOptions {
  bool estimate_scale = true;  // false: s = 1 (rigid)
  double scale_hint = 0;       // > 0: use this source → target scale instead of the radius ratio
  int max_points = 4000;       // per set, after voxel thinning
  bool use_pca = true;
  bool use_fpfh = true;
  int ransac_iterations = 20000;
  int refine_candidates = 6;   // best-scoring candidates refined by ICP
  int refine_iterations = 20;  // rigid ICP iterations per candidate
  uint64_t seed = 42;
  void Check() const;
};

struct GlobalRegistrationResult {
  core::Sim3 transform;        // source → target
  double inlier_fraction = 0;  // share of thinned source points within 2 voxels of the target
  double voxel = 0;            // thinning voxel, target units
  std::string method;          // "pca" or "fpfh" (which candidate won)
  int candidates = 0;          // refined by ICP
};

// Throws fmv3d::Error when either set has fewer than 10 points or no candidate overlaps at all.
GlobalRegistrationResult GlobalRegistration(const io::OrientedPointCloud& source, const io::OrientedPointCloud& target,
                                            const GlobalRegistrationOptions& options);

// Keeps one point (the first) per occupied voxel of the given size; attributes follow.
io::OrientedPointCloud VoxelThin(const io::OrientedPointCloud& cloud, double voxel);
// A voxel size that thins the cloud to about `target_points` (by bisection on the occupied voxel count).
double VoxelForCount(const io::OrientedPointCloud& cloud, int target_points);

}  // namespace fmv3d::align
