// The sparse stage's memory bound: matched keypoints counted once however many pairs share them.
#include "fmv3d/sfm/sparse_memory.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace fmv3d::sfm
