// The sparse stage's memory bound: matched keypoints counted once however many pairs share them.
#include "fmv3d/sfm/sparse_memory.h"

#include <gtest/gtest.h>

#include <map>

#include "fmv3d/features/types.h"

namespace fmv3d::sfm {
namespace {

features::VerifiedPair MemoryTestPair(uint32_t id1, uint32_t id2, std::vector<features::FeatureMatch> inliers) {
  features::VerifiedPair p;
  p.image_id1 = id1;
  p.image_id2 = id2;
  p.inliers = std::move(inliers);
  return p;
}

TEST(SparseMemory, MatchedKeypointsCountedOnceAcrossPairs) {
  // Image 1's keypoint 0 is matched in both pairs; image 3's keypoint 9 does not exist (ignored, not counted).
  const std::vector<features::VerifiedPair> pairs = {MemoryTestPair(1, 2, {{0, 0}, {1, 1}, {2, 2}}),
                                                     MemoryTestPair(1, 3, {{0, 4}, {3, 9}})};
  const SparseMemoryCounts c = CountSparseMemoryInputs({10, 5, 6}, pairs);
  EXPECT_EQ(c.keypoints, 21u);
  EXPECT_EQ(c.correspondences, 5u);
  // Image 1: 0, 1, 2, 3; image 2: 0, 1, 2; image 3: 4.
  EXPECT_EQ(c.matched_keypoints, 8u);
}

TEST(SparseMemory, BoundTakesEveryMatchedKeypointAsAnObservation) {
  SparseMemoryCounts c;
  c.keypoints = 1000000;
  c.matched_keypoints = 600000;
  c.correspondences = 3000000;
  // 700 × 600k + 350 × 1M + 40 × 3M bytes = 890 MB.
  EXPECT_NEAR(SparseMemoryBoundMb(c), 890e6 / 1048576.0, 1e-9);
  EXPECT_LT(EstimateSparseMemoryMb(400000, c.keypoints, c.correspondences), SparseMemoryBoundMb(c));
}

// Three images of 10 keypoints; keypoint k of each image is matched in the pairs (1,2), (2,3), (1,3) when k < 6, and
// only in (1,2) when k ≥ 6: the first six make three-view tracks, the rest two-view ones.
std::vector<features::VerifiedPair> TriangleOfPairs() {
  std::vector<features::VerifiedPair> pairs = {MemoryTestPair(1, 2, {}), MemoryTestPair(2, 3, {}),
                                               MemoryTestPair(1, 3, {})};
  for (uint32_t k = 0; k < 10; ++k) {
    pairs[0].inliers.push_back({k, k});
    if (k < 6) {
      pairs[1].inliers.push_back({k, k});
      pairs[2].inliers.push_back({k, k});
    }
  }
  for (auto& p : pairs) p.num_inliers_F = p.num_inliers_H = static_cast<uint32_t>(p.inliers.size());
  return pairs;
}

// A model in which each matched keypoint and each correspondence costs 1 MiB and keypoints nothing: bounds in units.
SparseMemoryModel OneMiBPerUnit() {
  SparseMemoryModel model;
  model.bytes_per_observation = 1048576;
  model.bytes_per_keypoint = 0;
  model.bytes_per_correspondence = 1048576;
  return model;
}

// Images whose keypoints lie at the positions given, or all at one point (one grid cell).
std::vector<MapperImage> ImagesAt(const std::vector<std::vector<Eigen::Vector2d>>& positions) {
  std::vector<MapperImage> images(positions.size());
  for (size_t i = 0; i < positions.size(); ++i) {
    images[i].id = static_cast<uint32_t>(i + 1);
    images[i].keypoints = positions[i];
  }
  return images;
}

std::vector<MapperImage> ImagesInOneCell(const std::vector<size_t>& counts) {
  std::vector<std::vector<Eigen::Vector2d>> positions(counts.size());
  for (size_t i = 0; i < counts.size(); ++i) positions[i].assign(counts[i], Eigen::Vector2d(50, 50));
  return ImagesAt(positions);
}

TEST(SparseMemory, ThinningKeepsTheMostConnectedKeypointsWithinTheBudget) {
  const std::vector<MapperImage> keypoints = ImagesInOneCell({10, 10, 10});
  SparseMemoryModel model = OneMiBPerUnit();
  std::vector<features::VerifiedPair> pairs = TriangleOfPairs();
  // Untouched: 26 matched keypoints (10 + 10 + 6), 22 correspondences, bound 48.
  const SparseThinning none = ThinToMemoryBudget(keypoints, {}, 100, &pairs, model);
  EXPECT_FALSE(none.thinned);
  EXPECT_TRUE(none.fits);
  EXPECT_EQ(none.before.matched_keypoints, 26u);
  EXPECT_EQ(none.before.correspondences, 22u);
  EXPECT_EQ(pairs[0].inliers.size(), 10u);

  // A budget of 40: each image keeps the same share of its matched keypoints, most connected first. 8 of 10 in
  // images 1 and 2 and 5 of 6 in image 3 give 21 matched + 18 correspondences = 39; one more keypoint each in
  // images 1 and 2 would give 42.
  const SparseThinning t = ThinToMemoryBudget(keypoints, {}, 40, &pairs, model);
  EXPECT_TRUE(t.thinned);
  EXPECT_TRUE(t.fits);
  EXPECT_DOUBLE_EQ(t.bound_after_mb, 39);
  EXPECT_EQ(t.after.correspondences, 18u);
  EXPECT_EQ(t.after.matched_keypoints, 21u);
  ASSERT_EQ(pairs[0].inliers.size(), 8u);
  EXPECT_EQ(pairs[0].inliers.back().idx1, 7u);  // the six three-view keypoints first, then the lowest indices
  EXPECT_EQ(pairs[0].num_inliers_F, 8u);        // geometry counts scaled with the inliers
  EXPECT_EQ(pairs[1].inliers.size(), 5u);
  EXPECT_EQ(pairs[2].inliers.size(), 5u);
  EXPECT_LT(t.keep_fraction, 1.0);
}

TEST(SparseMemory, TiePointsAreAlwaysKeptAndAnUnreachableBudgetChangesNothing) {
  const std::vector<MapperImage> keypoints = ImagesInOneCell({10, 10, 10});
  SparseMemoryModel model = OneMiBPerUnit();
  // Keypoints 8 and 9 of images 1 and 2 are the operator's tie points (two-view, the least connected).
  const std::map<uint32_t, uint32_t> manual_from = {{1, 8}, {2, 8}};
  std::vector<features::VerifiedPair> pairs = TriangleOfPairs();
  const SparseThinning t = ThinToMemoryBudget(keypoints, manual_from, 40, &pairs, model);
  ASSERT_TRUE(t.thinned);
  EXPECT_LE(t.bound_after_mb, 40);
  size_t ties = 0;
  for (const auto& m : pairs[0].inliers) ties += m.idx1 >= 8;
  EXPECT_EQ(ties, 2u);

  // Only the keypoints' own term is above the budget: no fraction fits, so nothing is dropped.
  model.bytes_per_keypoint = 1048576;  // 30 MiB before any match
  pairs = TriangleOfPairs();
  const SparseThinning u = ThinToMemoryBudget(keypoints, {}, 31, &pairs, model);
  EXPECT_FALSE(u.thinned);
  EXPECT_FALSE(u.fits);
  EXPECT_EQ(pairs[0].inliers.size(), 10u);
}

// Images 1 and 2: keypoints 0–4 on the left (x = 10), matched in all three pairs; 5–9 on the right (x = 900),
// matched in (1, 2) only. Ranking by connection alone would keep the left side only; the grid keeps both.
TEST(SparseMemory, ThinningKeepsKeypointsAcrossTheImage) {
  std::vector<std::vector<Eigen::Vector2d>> positions(3);
  for (int k = 0; k < 10; ++k) {
    const Eigen::Vector2d at(k < 5 ? 10 : 900, 100 + 10 * (k % 5));
    positions[0].push_back(at);
    positions[1].push_back(at);
    if (k < 5) positions[2].push_back(at);
  }
  std::vector<features::VerifiedPair> pairs = {MemoryTestPair(1, 2, {}), MemoryTestPair(1, 3, {}),
                                               MemoryTestPair(2, 3, {})};
  for (uint32_t k = 0; k < 10; ++k) {
    pairs[0].inliers.push_back({k, k});
    if (k < 5) {
      pairs[1].inliers.push_back({k, k});
      pairs[2].inliers.push_back({k, k});
    }
  }
  SparseMemoryModel model = OneMiBPerUnit();
  // Before: 25 matched + 20 correspondences. Keeping 6 of 10 in images 1 and 2 (3 a side) and 3 of 5 in image 3
  // gives 15 + 12 = 27; one more in images 1 and 2 and image 3's fourth give 33.
  const SparseThinning t = ThinToMemoryBudget(ImagesAt(positions), {}, 30, &pairs, model);
  ASSERT_TRUE(t.thinned);
  EXPECT_DOUBLE_EQ(t.bound_after_mb, 27);
  size_t left = 0, right = 0;
  for (const auto& m : pairs[0].inliers) (m.idx1 < 5 ? left : right) += 1;
  EXPECT_EQ(left, 3u);
  EXPECT_EQ(right, 3u);
}

}  // namespace
}  // namespace fmv3d::sfm
