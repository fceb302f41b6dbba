// Memory of the sparse stage, stated before the mapper runs and after it.
//
// Bundle adjustment needs every observation of the model at once, so the stage's peak grows with the model rather
// than with a window the stage could choose: the Ceres problem and its Jacobian (≈ 170–186 B per observation), the
// Schur eliminator, the nested-model copies of the points; the correspondence graph and the image arrays (≈ 80 B per
// keypoint, with the keypoints themselves); the verified pairs' inlier lists (8 B per correspondence, held twice
// more in the graph). Fitted as a bound on heaptrack and peak-RSS measurements (bench/results/scale11.md, mem12.md):
//   bytes ≤ 700 × observations + 350 × keypoints + 40 × correspondences   (the process's ~105 MiB base not counted)
// Before mapping the observations are not known; each keypoint that takes part in a verified correspondence can be
// at most one observation, so their count bounds them. The stage cannot trade this memory for time the way the
// windowed stages do; it keeps within a budget by mapping fewer observations: ThinToMemoryBudget keeps each image's
// most connected matched keypoints (those that make long tracks, which tie the cameras together), spread over the
// image, and drops the correspondences of the rest, the operator's tie points always kept.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <vector>

#include "fmv3d/sfm/incremental_mapper.h"

namespace fmv3d::sfm {

struct SparseMemoryModel {
  double bytes_per_observation = 700;
  double bytes_per_keypoint = 350;
  double bytes_per_correspondence = 40;
};

struct SparseMemoryCounts {
  size_t keypoints = 0;          // every keypoint of every image (tie points included)
  size_t matched_keypoints = 0;  // those in at least one verified correspondence: a bound on the observations
  size_t correspondences = 0;    // inliers over all verified pairs
};

// `keypoints_per_image[i]` is image id i + 1's keypoint count (pairs use 1-based ids). Pair indices outside their
// image are ignored here (the match reader refuses them).
SparseMemoryCounts CountSparseMemoryInputs(const std::vector<size_t>& keypoints_per_image,
                                           const std::vector<features::VerifiedPair>& pairs);

// The model's MiB for `observations` observations (MiB = 2^20 bytes, as the other stages' budgets).
double EstimateSparseMemoryMb(size_t observations, size_t keypoints, size_t correspondences,
                              const SparseMemoryModel& model = {});

// The bound before mapping: every matched keypoint taken as an observation.
inline double SparseMemoryBoundMb(const SparseMemoryCounts& c, const SparseMemoryModel& model = {}) {
  return EstimateSparseMemoryMb(c.matched_keypoints, c.keypoints, c.correspondences, model);
}

struct SparseThinning {
  SparseMemoryCounts before, after;
  double bound_before_mb = 0, bound_after_mb = 0;
  double keep_fraction = 1;  // of each image's matched automatic keypoints, the most connected first
  bool thinned = false;
  bool fits = true;  // the bound (after thinning, if any) is within the budget
};

// Keeps the bound within `budget_mb` by dropping the correspondences of part of each image's matched keypoints:
// each image keeps the same share of them, spread over an 8 × 8 grid of its keypoints' extent (so the pairs'
// geometry keeps its field of view) and the most connected first within a cell (fewest correspondences dropped
// first; ties by index, so the result is deterministic). The largest share in [min_keep_fraction, 1] that fits is
// found by bisection. Keypoints at or after `manual_from[image id]` (the operator's tie points) are always kept.
// When even `min_keep_fraction` does not fit (the keypoints' own term is too large), `pairs` is left unchanged and
// `fits` is false: thinning further would cost the model without meeting the budget.
SparseThinning ThinToMemoryBudget(const std::vector<MapperImage>& images,
                                  const std::map<uint32_t, uint32_t>& manual_from, double budget_mb,
                                  std::vector<features::VerifiedPair>* pairs, const SparseMemoryModel& model = {},
                                  double min_keep_fraction = 0.2);

}  // namespace fmv3d::sfm
