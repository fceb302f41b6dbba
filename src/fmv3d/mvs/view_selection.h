// Global view selection (after Goesele et al. 2007): for every reference view, the other views that see the
// same surface from a useful angle at a similar scale, and the depth range PatchMatch searches.
//
// A candidate j of reference r is scored over the sparse points r observes that j observes too:
//   score_j = Σ_X  w_angle(α) · w_scale(X)
//   w_angle = min(1, (α / α_good)²) for α in [min_angle, max_angle], else 0   (α: triangulation angle at X)
//   w_scale = s if s < 1, 1 if 1 ≤ s ≤ 2, 2/s if s > 2                        (s: pixel footprint r / j)
// so wide-enough baselines and equal or finer resolution win. A model without sparse points (e.g. ground-truth
// cameras only) is handled with stand-in points: a grid of the reference's rays at the depth where the
// cameras' optical axes converge.
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
  void Check() const;
};

struct Neighbour {
  uint32_t image_id = 0;
  double score = 0;
  double median_angle_deg = 0;
  int shared_points = 0;
};

struct ReferenceSelection {
  std::vector<Neighbour> neighbours;  // best first; empty when the view has no usable neighbour
  double depth_min = 0, depth_max = 0;  // camera-frame z range to search; 0 when unknown
  bool from_sparse_points = false;      // false: stand-in points were used
  std::string problem;                  // why the view cannot be used (empty when it can)
};

std::map<uint32_t, ReferenceSelection> SelectViews(const core::Reconstruction& rec,
                                                   const std::map<uint32_t, ViewGeometry>& geoms,
                                                   const ViewSelectionOptions& options);

}  // namespace fmv3d::mvs
