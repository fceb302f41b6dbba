// Union–find tracks on hand-made correspondence graphs with exact expected tracks: transitive merges, a closed
// cycle, conflicts cut at the weakest pair, invalid matches skipped; and a model's coverage of the tracks.
#include "fmv3d/sfm/track_builder.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>

namespace fmv3d::sfm {
namespace {

using Track = std::vector<std::pair<uint32_t, uint32_t>>;  // (image, keypoint), sorted by image

features::VerifiedPair Pair(uint32_t a, uint32_t b, const std::vector<std::pair<uint32_t, uint32_t>>& matches) {
  features::VerifiedPair p;
  p.image_id1 = a;
  p.image_id2 = b;
  for (const auto& [i, j] : matches) p.inliers.push_back({i, j});
  return p;
}

std::set<Track> AsSet(const TrackSet& ts) {
  std::set<Track> out;
  for (const auto& t : ts.tracks) {
    Track tr;
    for (const auto& el : t) tr.emplace_back(el.image_id, el.point2d_idx);
    out.insert(tr);
  }
  return out;
}

const std::map<uint32_t, size_t> kFourImages = {{1, 10}, {2, 10}, {3, 10}, {4, 10}};

TEST(TrackBuilder, TransitiveMergesAndAClosedCycle) {
  // 1:0–2:0–3:0–4:0 chained pair by pair, and the cycle closed by 1:0–4:0 (same track, no conflict);
  // 1:1–2:1, 2:1–3:1 chain; 1:5–2:5 stays a two-view track; a duplicate match is counted once.
  const std::vector<features::VerifiedPair> pairs = {Pair(1, 2, {{0, 0}, {1, 1}, {5, 5}, {5, 5}}),
                                                     Pair(2, 3, {{0, 0}, {1, 1}}), Pair(3, 4, {{0, 0}}),
                                                     Pair(1, 4, {{0, 0}})};
  const TrackSet ts = BuildTracks(kFourImages, pairs);
  const std::set<Track> expected = {{{1, 0}, {2, 0}, {3, 0}, {4, 0}}, {{1, 1}, {2, 1}, {3, 1}}, {{1, 5}, {2, 5}}};
  EXPECT_EQ(AsSet(ts), expected);
  EXPECT_EQ(ts.num_conflicts, 0u);
  EXPECT_EQ(ts.num_links, 6u);  // 3 + 2 + 1: the duplicate and the cycle's closing match add nothing
  EXPECT_DOUBLE_EQ(ts.MeanLength(), 3.0);
  EXPECT_DOUBLE_EQ(ts.MeanLengthMultiView(), 3.5);
}

TEST(TrackBuilder, ConflictIsCutAtTheWeakestPair) {
  // 1:0–2:0 and 2:0–3:0, then 1:1–3:0 would put keypoints 0 and 1 of image 1 in one track. The pair carrying
  // the conflicting link has the fewest inliers: that link is cut, both other links stay.
  std::vector<features::VerifiedPair> pairs = {Pair(1, 3, {{1, 0}}), Pair(1, 2, {{0, 0}, {7, 7}, {8, 8}}),
                                               Pair(2, 3, {{0, 0}, {7, 7}})};
  TrackSet ts = BuildTracks(kFourImages, pairs);
  std::set<Track> expected = {{{1, 0}, {2, 0}, {3, 0}}, {{1, 7}, {2, 7}, {3, 7}}, {{1, 8}, {2, 8}}};
  EXPECT_EQ(AsSet(ts), expected);
  EXPECT_EQ(ts.num_conflicts, 1u);
  // The same matches with the (1, 3) pair the strongest: now 2:0–3:0 is the weakest link on the chain.
  pairs[0] = Pair(1, 3, {{1, 0}, {7, 7}, {8, 8}, {9, 9}});
  ts = BuildTracks(kFourImages, pairs);
  expected = {{{1, 1}, {3, 0}}, {{1, 0}, {2, 0}}, {{1, 7}, {2, 7}, {3, 7}}, {{1, 8}, {2, 8}, {3, 8}}, {{1, 9}, {3, 9}}};
  EXPECT_EQ(AsSet(ts), expected);
  EXPECT_EQ(ts.num_conflicts, 1u);
}

TEST(TrackBuilder, InvalidMatchesAreSkipped) {
  // Keypoint out of range, an unknown image, an image paired with itself.
  const std::vector<features::VerifiedPair> pairs = {Pair(1, 2, {{0, 0}, {10, 1}}), Pair(1, 9, {{2, 2}}),
                                                     Pair(3, 3, {{1, 2}})};
  const TrackSet ts = BuildTracks(kFourImages, pairs);
  EXPECT_EQ(AsSet(ts), (std::set<Track>{{{1, 0}, {2, 0}}}));
  EXPECT_EQ(ts.num_links, 1u);
}

TEST(TrackBuilder, CoverageCountsHeldAndSplitTracks) {
  const std::vector<features::VerifiedPair> pairs = {Pair(1, 2, {{0, 0}, {1, 1}}), Pair(2, 3, {{0, 0}, {1, 1}}),
                                                     Pair(3, 4, {{0, 0}})};
  const TrackSet ts = BuildTracks(kFourImages, pairs);  // {1:0 2:0 3:0 4:0}, {1:1 2:1 3:1}
  core::Reconstruction rec;
  for (uint32_t id = 1; id <= 4; ++id) {
    rec.images[id].id = id;
    rec.images[id].point3d_ids.assign(10, core::kNoPoint3D);
  }
  auto observe = [&](uint64_t pid, uint32_t image, uint32_t kp) {
    rec.points[pid].track.push_back({image, kp});
    rec.images[image].point3d_ids[kp] = static_cast<int64_t>(pid);
  };
  observe(1, 1, 0);  // the first track as two points: 1:0 2:0, and 3:0 4:0
  observe(1, 2, 0);
  observe(2, 3, 0);
  observe(2, 4, 0);
  observe(3, 1, 1);  // the second track: two of its three keypoints
  observe(3, 2, 1);
  const TrackCoverage c = MeasureTrackCoverage(ts, rec);
  EXPECT_EQ(c.points, 3u);
  EXPECT_EQ(c.observations, 6u);
  EXPECT_EQ(c.tracks_touched, 2u);
  EXPECT_EQ(c.keypoints_of_touched_tracks, 7u);
  EXPECT_EQ(c.held_of_touched_tracks, 6u);
  EXPECT_EQ(c.tracks_split, 1u);
}

}  // namespace
}  // namespace fmv3d::sfm
