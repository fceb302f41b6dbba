// Track completion guided by projection: every 3D point is projected into the registered images that could see
// it but do not observe it, and a keypoint near the projection joins its track when its descriptor looks like
// the track's own.
//
// Why: the correspondence graph only holds what the pairwise matcher kept. The ratio test drops a true match
// whenever an image has a similar-looking second candidate anywhere in it (repeated texture, the other
// orientation of the same keypoint), so a point seen by six images is often matched in four. Once the point and
// the cameras are known, the search for its keypoint in another image is local (a few pixels around the
// projection instead of the whole image), and the descriptor test only has to tell the point from the keypoints
// that happen to lie that close. Longer tracks tie the cameras together more tightly.
//
// Candidates: images that share a verified pair with one of the point's images (co-visible ones; a video's
// model is never projected into all its frames), registered, not yet in the track. The search radius is the
// triangulator's reprojection bound; only keypoints that observe no point are taken, the one most similar to
// the track's descriptors (smallest distance to any of them). The descriptor bound controls false additions:
// every search is repeated at a decoy location half an image away, where a keypoint is this point only by
// chance, and a candidate is accepted when it is closer than all but a false_accept_rate share of the decoys.
// A keypoint claimed by several points goes to the one it resembles most. Observations that do not fit after
// the caller's bundle adjustment are filtered with every other one.
#pragma once

#include <cstdint>
#include <map>
#include <set>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

struct GuidedCompletionOptions {
  double max_error_px = 4;          // search radius around the projection (pixels)
  double false_accept_rate = 0.01;  // share of the decoy searches the descriptor bound lets through
  int min_decoys_for_bound = 200;   // fewer decoy searches found a keypoint: no bound is measured, nothing added
  void Check() const;
};

struct GuidedCompletionStats {
  size_t points = 0;            // points tried
  size_t projections = 0;       // (point, image) projections inside an image
  size_t candidates = 0;        // of those: with a free keypoint inside the radius
  size_t accepted = 0;          // observations added
  size_t conflicts = 0;         // keypoints claimed by more than one point (the most similar one kept)
  size_t decoys = 0;            // decoy searches that found a keypoint (the bound's sample)
  double descriptor_bound = 0;  // squared L2 distance on the uint8 descriptors
  size_t member_distances = 0;  // observations of points with ≥ 2 described ones
  double member_median = 0;     // their median squared distance to the nearest fellow member (for the report)
};

// Adds observations to the points of *rec. `descriptors` maps an image id to its descriptors (row k belongs to
// rec->images[id].points2d[k]; images without an entry are neither searched nor used for the bound);
// `covisible` maps an image id to the images it shares a verified pair with. Points and cameras are not moved:
// the caller's bundle adjustment follows.
GuidedCompletionStats CompleteTracksByProjection(core::Reconstruction* rec,
                                                 const std::map<uint32_t, const features::Descriptors*>& descriptors,
                                                 const std::map<uint32_t, std::set<uint32_t>>& covisible,
                                                 const GuidedCompletionOptions& options);

}  // namespace fmv3d::sfm
