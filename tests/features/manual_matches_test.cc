// The operator's tie points as feature correspondences: appended keypoints and their layout, tie-point matches
// added to verified pairs (and pairs created for frames automatic matching did not pair), disagreement with an
// automatic F reported, single-frame keypoints found along the epipolar line by descriptor, deleted matches
// removed, and matches/manual.json read back as written.
#include "fmv3d/features/manual_matches.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::features {
namespace {

io::FramesIndex Index(int n) {
  io::FramesIndex index;
  io::CameraPrior c;
  c.camera = core::Camera::Pinhole(640, 480, 500);
  index.cameras.push_back(c);
  for (int i = 0; i < n; ++i) {
    io::FrameRecord f;
    f.name = "f" + std::to_string(i) + ".png";
    index.frames.push_back(f);
  }
  return index;
}

FeatureSet Features(int n, uint64_t seed) {
  FeatureSet f;
  f.width = 640;
  f.height = 480;
  std::mt19937 rng(static_cast<unsigned>(seed));
  std::uniform_real_distribution<float> u(10, 470);
  f.descriptors.resize(n, 128);
  for (int i = 0; i < n; ++i) {
    f.keypoints.push_back({u(rng), u(rng), 2, 0});
    for (int k = 0; k < 128; ++k) f.descriptors(i, k) = static_cast<uint8_t>(rng() % 256);
    f.colors.push_back({1, 2, 3});
  }
  return f;
}

// A pure sideways translation: F maps a point to the horizontal line through it (same row).
Eigen::Matrix3d SidewaysF() {
  Eigen::Matrix3d F;
  F << 0, 0, 0, 0, 0, -1, 0, 1, 0;
  return F;
}

TEST(ManualMatches, TiePointsAddedKeptAndReported) {
  const auto index = Index(3);
  std::vector<FeatureSet> feats = {Features(50, 1), Features(60, 2), Features(70, 3)};
  std::vector<VerifiedPair> pairs(1);
  pairs[0].image_id1 = 1;
  pairs[0].image_id2 = 2;
  pairs[0].F = SidewaysF();
  pairs[0].inliers = {{3, 4}, {5, 6}};
  pairs[0].geometry = PairGeometry::kUncalibrated;
  pairs[0].num_inliers_F = 40;  // an F that can judge (see below)
  io::TiePoints t;
  // On the epipolar line in f0/f1 (same row), and seen in f2 (no automatic pair with either).
  t.tie_points.push_back({"a", "", {{"f0.png", 100, 200}, {"f1.png", 150, 200.5}, {"f2.png", 300, 100}}});
  // 30 px off the line.
  t.tie_points.push_back({"b", "", {{"f0.png", 100, 300}, {"f1.png", 150, 330}}});
  t.deleted_matches.push_back({"f1.png", "f0.png", 6, 5});  // frame order reversed: still found
  t.deleted_matches.push_back({"f0.png", "f1.png", 7, 7});  // not a match
  ManualMatchOptions o;
  // An F from matches on one plane, or from a few inliers, is not determined off them: nothing is judged by it.
  for (const auto& [geometry, inliers] :
       {std::make_pair(PairGeometry::kPlanarOrRotation, 40u), std::make_pair(PairGeometry::kUncalibrated, 15u)}) {
    std::vector<FeatureSet> f2 = feats;
    std::vector<VerifiedPair> p2 = pairs;
    p2[0].geometry = geometry;
    p2[0].num_inliers_F = inliers;
    ManualMatches m2 = AppendManualKeypoints(t, index, {}, &f2, o);
    ApplyManualMatches(t, index, f2, o, &m2, &p2);
    EXPECT_TRUE(m2.disagreeing.empty()) << inliers;
  }
  ManualMatches m = AppendManualKeypoints(t, index, {}, &feats, o);
  ASSERT_EQ(m.appended.size(), 3u);
  EXPECT_EQ(m.appended.at(0).first_index, 50u);
  EXPECT_EQ(feats[0].keypoints.size(), 52u);
  EXPECT_EQ(feats[0].descriptors.rows(), 52);
  EXPECT_EQ(feats[0].colors.size(), 52u);
  EXPECT_FLOAT_EQ(feats[1].keypoints[61].y, 330);
  ApplyManualMatches(t, index, feats, o, &m, &pairs);
  ASSERT_EQ(pairs.size(), 3u);  // f0-f1 kept, f0-f2 and f1-f2 created
  const auto& p01 = pairs[0];
  // (3,4) stays, (5,6) deleted, tie points a (50↔60) and b (51↔61) added.
  ASSERT_EQ(p01.inliers.size(), 3u);
  EXPECT_EQ(p01.inliers[0].idx1, 3u);
  EXPECT_EQ(p01.inliers[1].idx1, 50u);
  EXPECT_EQ(p01.inliers[1].idx2, 60u);
  EXPECT_EQ(p01.inliers[2].idx2, 61u);
  EXPECT_EQ(m.deleted, 1u);
  EXPECT_EQ(m.deleted_not_found, 1u);
  ASSERT_EQ(m.disagreeing.size(), 1u);
  EXPECT_EQ(m.disagreeing[0].id, "b");
  EXPECT_NEAR(m.disagreeing[0].epipolar_px, 30, 1e-9);
  EXPECT_EQ(pairs[1].image_id1, 1u);
  EXPECT_EQ(pairs[1].image_id2, 3u);
  EXPECT_EQ(pairs[1].inliers.size(), 1u);
  EXPECT_EQ(pairs[1].inliers[0].idx2, 70u);
  // manual.json round trip.
  const auto back = ManualMatches::FromJson(m.ToJson(index), index);
  ASSERT_EQ(back.appended.size(), 3u);
  EXPECT_EQ(back.appended.at(1).first_index, 60u);
  EXPECT_EQ(back.appended.at(1).descriptors, m.appended.at(1).descriptors);
  ASSERT_EQ(back.tracks.size(), 2u);
  EXPECT_EQ(back.tracks[0].observations.size(), 3u);
  EXPECT_EQ(back.tracks[0].observations[2].keypoint, 70u);
  // Unknown frames are refused.
  io::TiePoints bad;
  bad.tie_points.push_back({"x", "", {{"f0.png", 1, 1}, {"nope.png", 1, 1}}});
  EXPECT_THROW(AppendManualKeypoints(bad, index, {}, &feats, o), Error);
}

TEST(ManualMatches, SingleFrameKeypointFoundAlongEpipolarLine) {
  const auto index = Index(2);
  std::vector<FeatureSet> feats = {Features(40, 4), Features(40, 5)};
  std::vector<VerifiedPair> pairs(1);
  pairs[0].image_id1 = 1;
  pairs[0].image_id2 = 2;
  pairs[0].F = SidewaysF();
  pairs[0].inliers = {{0, 0}};
  // Frame 1's keypoint 7 sits on the clicked point's row; a twin descriptor elsewhere (off the line) must lose.
  feats[1].keypoints[7] = {400, 222, 2, 0};
  io::TiePoints t;
  t.keypoints.push_back({"k", "", {"f0.png", 120, 222}});
  ManualMatches m = AppendManualKeypoints(t, index, {}, &feats, {});
  feats[0].descriptors.row(40) = feats[1].descriptors.row(7);  // the clicked point looks like keypoint 7
  feats[1].descriptors.row(9) = feats[1].descriptors.row(7);
  feats[1].keypoints[9] = {400, 300, 2, 0};
  ApplyManualMatches(t, index, feats, {}, &m, &pairs);
  EXPECT_EQ(m.keypoints_matched, 1u);
  ASSERT_EQ(m.tracks[0].observations.size(), 2u);
  EXPECT_EQ(m.tracks[0].observations[1].image, 1u);
  EXPECT_EQ(m.tracks[0].observations[1].keypoint, 7u);
  ASSERT_EQ(pairs[0].inliers.size(), 2u);
  EXPECT_EQ(pairs[0].inliers[1].idx1, 40u);
  EXPECT_EQ(pairs[0].inliers[1].idx2, 7u);
}

}  // namespace
}  // namespace fmv3d::features
