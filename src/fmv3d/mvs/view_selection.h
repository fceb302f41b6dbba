// Global view selection (after Goesele et al. 2007): for every reference view, the other views that see the
// same surface from a useful angle at a similar scale, and the depth range PatchMatch searches.
//
// A candidate j of reference r is scored over the sparse points r observes that j observes too:
//   score_j = Σ_X  w_angle(α) · w_scale(X)
//   w_angle = min(1, (α / α_good)²) for α in [min_angle, max_angle], else 0   (α: triangulation angle at X)
//   w_scale = s if s < 1, 1 if 1 ≤ s ≤ 2, 2/s if s > 2                        (s: pixel footprint r / j)
// so wide-enough baselines and equal or finer resolution win; the order then favours covering the whole
// reference (coverage_sources below). A model without sparse points (e.g. ground-truth cameras only) is handled
// with stand-in points: a grid of the reference's rays at the depth where the cameras' optical axes converge.
// Candidates share a point by track or by sight (sources_by_projection), so sources can come from anywhere in
// the clip; the depth range reaches as far as the widest chosen baseline resolves (far_parallax_px).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/mvs/view.h"

namespace fmv3d::mvs {

struct ViewSelectionOptions {
  int max_neighbours = 10;       // candidates kept per reference (stereo uses the best few, fusion all)
  int min_shared_points = 8;     // fewer shared points: not a neighbour
  double min_angle_deg = 1.0;    // median triangulation angle below this: too little parallax
  double max_angle_deg = 60.0;   // above this: the patches look too different
  double good_angle_deg = 10.0;  // angle from which a shared point counts fully
  // A sparse point is shared with j also when j sees it (projects into j, on the reference's side, at 0.5–2x
  // the distance) without being in its track; false: tracks only.
  bool sources_by_projection = true;
  // Depth range: up to where the widest chosen baseline gives this parallax (0 = the sparse points' range
  // only), at most max_far_factor × the 99th percentile of the sparse depths.
  double far_parallax_px = 2.0;
  double max_far_factor = 10.0;
  // Order of the kept candidates (stereo takes the first few): greedy coverage of the reference's image by
  // coverage_sources views (PatchMatch's top_k), with each candidate's score weighted by
  // coverage_score_weight against the share of the image it newly covers; coverage_score_weight alone decides
  // once the image is covered.
  int coverage_sources = 3;
  double coverage_score_weight = 0.25;
  void Check() const;
};

struct Neighbour {
  uint32_t image_id = 0;
  double score = 0;
  double median_angle_deg = 0;
  int shared_points = 0;
};

struct ReferenceSelection {
  std::vector<Neighbour> neighbours;    // best first; empty when the view has no usable neighbour
  double depth_min = 0, depth_max = 0;  // camera-frame z range to search; 0 when unknown
  bool from_sparse_points = false;      // false: stand-in points were used
  std::string problem;                  // why the view cannot be used (empty when it can)
};

// Reference views for a redundant capture (video keyframes, where every surface point is in ~20 views): the
// fewest views, greedily, such that each sparse point is seen by min(coverage, views that see it) of them — a
// set multi-cover after CMVS (Furukawa et al. 2010). Depth maps cost per reference and fusion merges the same
// surface once per reference, so this cuts dense, fusion, Poisson and texture time in proportion; the views
// left out still serve as stereo sources.
// "Sees" is not the SfM track alone (video tracks break into many 2-view pieces, which would force every view
// in): a view sees a point when the point projects into it, from within cone_deg of the point's mean observed
// direction, at 0.5–2x its observed distance (occlusion is not modelled: the cone keeps views on the far side
// of an object out). Stops when the chosen views meet `demand_fraction` of the total demand (the last points
// are at the capture's edge and would pull in views for almost nothing). Returns every candidate when
// coverage <= 0 or the model has no sparse points (e.g. ground-truth cameras only). Sorted by image id.
struct ReferenceCoverOptions {
  int coverage = 0;
  double demand_fraction = 0.98;
  double cone_deg = 45;
};
std::vector<uint32_t> SelectReferenceViews(const core::Reconstruction& rec,
                                           const std::map<uint32_t, ViewGeometry>& geoms,
                                           const std::vector<uint32_t>& candidates,
                                           const ReferenceCoverOptions& options);

std::map<uint32_t, ReferenceSelection> SelectViews(const core::Reconstruction& rec,
                                                   const std::map<uint32_t, ViewGeometry>& geoms,
                                                   const ViewSelectionOptions& options);

}  // namespace fmv3d::mvs
