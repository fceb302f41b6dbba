// Tracks by union–find over every verified pair's matches: what the matches allow, before any geometry. A match
// links two keypoints; linked keypoints form one track. A track may hold one keypoint per image only: a link that
// would join two tracks seen in a common image is a conflict (a wrong or ambiguous match somewhere on the chain).
// Links are taken strongest pair first (most inliers, the most reliable verification), so a conflicting link is
// always the weakest on its chain and is the one cut; the rest of both tracks stays.
//
// The mapper does not triangulate these tracks blindly (a wrong match would chain unrelated points, see
// correspondence_graph.h): it grows its tracks over the correspondence graph by reprojection error. These tracks
// are the yardstick: their mean length is the longest the mapper's tracks can be on the same matches, and the
// mapper reports how much of them its model holds (report/sparse.json, "tracks").
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

struct TrackSet {
  std::vector<std::vector<core::TrackElement>> tracks;  // each sorted by image id, ≥ 2 elements
  size_t num_links = 0;                                 // matches used (valid, distinct)
  size_t num_conflicts = 0;  // links cut: they would put two keypoints of an image in one track
  // Mean number of keypoints per track, over all tracks and over those seen in ≥ 3 images (the ones a mapper that
  // skips two-view tracks can triangulate).
  double MeanLength() const;
  double MeanLengthMultiView() const;
};

// num_keypoints: image id → keypoint count; matches naming unknown images or out-of-range keypoints are skipped,
// as by CorrespondenceGraph.
TrackSet BuildTracks(const std::map<uint32_t, size_t>& num_keypoints, const std::vector<features::VerifiedPair>& pairs);

// How much of the tracks a model holds: its observations (the mapper's mean track length is observations /
// points, as COLMAP reports it) and the keypoints of the tracks it touches, held or not.
struct TrackCoverage {
  size_t points = 0, observations = 0;
  size_t tracks_touched = 0, keypoints_of_touched_tracks = 0, held_of_touched_tracks = 0;
  size_t tracks_split = 0;  // tracks whose keypoints belong to more than one point of the model
};
TrackCoverage MeasureTrackCoverage(const TrackSet& tracks, const core::Reconstruction& rec);

}  // namespace fmv3d::sfm
