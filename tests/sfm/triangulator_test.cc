// The incremental triangulator on exact synthetic views: creation, transitive completion, merging, the
// parallax rule and a wrong match, with exact counts.
#include "fmv3d/sfm/triangulator.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "fmv3d/sfm/correspondence_graph.h"
#include "fmv3d/sfm/mapper_primitives.h"

namespace fmv3d::sfm {
namespace {

constexpr int kPoints = 30;

// Four cameras on an arc 10 m from a cloud of 30 points, all visible in every image; keypoint k of every
// image is point k (exact projections). pairs: the verified pairs, as (image a, image b), keypoint k ↔ k.
struct Views {
  core::Reconstruction rec;  // registered images, no points
  std::vector<Eigen::Vector3d> X;
  std::vector<features::VerifiedPair> pairs;
  std::map<uint32_t, size_t> num_kp;
};

Views MakeViews(const std::vector<std::pair<uint32_t, uint32_t>>& pairs, double arc_deg = 40) {
  Views v;
  v.rec.cameras[1] = core::Camera::Pinhole(1000, 800, 900);
  for (int k = 0; k < kPoints; ++k) v.X.emplace_back(std::sin(1.3 * k), std::cos(0.7 * k), 0.5 * std::sin(2.1 * k));
  for (uint32_t id = 1; id <= 4; ++id) {
    const double a = arc_deg * M_PI / 180 * (static_cast<double>(id) - 2.5) / 3;
    core::Image im;
    im.id = id;
    im.camera_id = 1;
    im.name = std::to_string(id);
    im.pose = core::Pose::LookAt(Eigen::Vector3d(10 * std::sin(a), -10 * std::cos(a), 1), Eigen::Vector3d::Zero());
    for (const auto& X : v.X) im.points2d.push_back(v.rec.cameras[1].Project(im.pose.Transform(X)));
    im.point3d_ids.assign(kPoints, core::kNoPoint3D);
    v.num_kp[id] = kPoints;
    v.rec.images[id] = im;
  }
  for (const auto& [a, b] : pairs) {
    features::VerifiedPair p;
    p.image_id1 = a;
    p.image_id2 = b;
    for (uint32_t k = 0; k < kPoints; ++k) p.inliers.push_back({k, k});
    v.pairs.push_back(p);
  }
  return v;
}

// Every point's track holds keypoint k of each image for one k.
void ExpectConsistentTracks(const core::Reconstruction& rec) {
  for (const auto& [pid, p] : rec.points) {
    ASSERT_FALSE(p.track.empty());
    for (const auto& el : p.track) {
      EXPECT_EQ(el.point2d_idx, p.track[0].point2d_idx) << "point " << pid;
      EXPECT_EQ(rec.images.at(el.image_id).point3d_ids[el.point2d_idx], static_cast<int64_t>(pid));
    }
  }
}

TEST(IncrementalTriangulator, ChainOfPairsGivesFullLengthTracks) {
  // Only consecutive pairs are verified: 1–2, 2–3, 3–4. Image 1's keypoints reach images 3 and 4 only through
  // the chain, so full tracks need the transitive completion.
  Views v = MakeViews({{1, 2}, {2, 3}, {3, 4}});
  const CorrespondenceGraph graph(v.num_kp, v.pairs);
  IncrementalTriangulator tri(graph, &v.rec, {});
  EXPECT_EQ(tri.TriangulateImage(1), kPoints);
  EXPECT_EQ(v.rec.points.size(), static_cast<size_t>(kPoints));
  for (const auto& [pid, p] : v.rec.points) {
    EXPECT_EQ(p.track.size(), 4u);
    const Eigen::Vector3d& truth = v.X[p.track[0].point2d_idx];
    EXPECT_LT((p.xyz - truth).norm(), 1e-9);
  }
  ExpectConsistentTracks(v.rec);
  // Nothing left to add: a second pass changes nothing.
  EXPECT_EQ(tri.Retriangulate(), 0);
}

TEST(IncrementalTriangulator, MergesPointsJoinedByACorrespondence) {
  Views v = MakeViews({{1, 2}, {2, 3}, {3, 4}});
  const CorrespondenceGraph graph(v.num_kp, v.pairs);
  IncrementalTriangulator tri(graph, &v.rec, {});
  std::vector<int64_t> first, second;
  for (uint32_t k = 0; k < kPoints; ++k) {
    first.push_back(tri.CreatePoint({{1, k}, {2, k}}));
    second.push_back(tri.CreatePoint({{3, k}, {4, k}}));
    ASSERT_NE(first.back(), core::kNoPoint3D);
    ASSERT_NE(second.back(), core::kNoPoint3D);
  }
  EXPECT_EQ(v.rec.points.size(), static_cast<size_t>(2 * kPoints));
  for (uint32_t k = 0; k < kPoints; ++k) EXPECT_EQ(tri.MergePoint(static_cast<uint64_t>(first[k])), 1);
  EXPECT_EQ(v.rec.points.size(), static_cast<size_t>(kPoints));
  for (const auto& [pid, p] : v.rec.points) EXPECT_EQ(p.track.size(), 4u);
  ExpectConsistentTracks(v.rec);
}

TEST(IncrementalTriangulator, RejectsAWrongMatchAndTooLittleParallax) {
  Views v = MakeViews({{1, 2}, {1, 3}, {1, 4}});
  // A wrong observation in the candidate list: keypoint 0 of image 1 with keypoint 7 of image 2.
  {
    const CorrespondenceGraph graph(v.num_kp, v.pairs);
    IncrementalTriangulator tri(graph, &v.rec, {});
    const int64_t pid = tri.CreatePoint({{1, 0}, {2, 7}, {3, 0}, {4, 0}});
    ASSERT_NE(pid, core::kNoPoint3D);
    const auto& p = v.rec.points.at(static_cast<uint64_t>(pid));
    EXPECT_EQ(p.track.size(), 3u);
    EXPECT_FALSE(PointHasImage(v.rec, static_cast<uint64_t>(pid), 2));
    EXPECT_EQ(v.rec.images.at(2).point3d_ids[7], core::kNoPoint3D);
  }
  // Cameras 0.5° apart around the cloud: every ray pair is narrower than the 1.5° minimum.
  Views narrow = MakeViews({{1, 2}}, 0.5);
  const CorrespondenceGraph graph(narrow.num_kp, narrow.pairs);
  TriangulatorOptions two_views;
  two_views.ignore_two_view_tracks = false;  // one pair: every track has two views
  IncrementalTriangulator tri(graph, &narrow.rec, two_views);
  EXPECT_EQ(tri.CreatePoint({{1, 3}, {2, 3}}), core::kNoPoint3D);
  EXPECT_EQ(tri.TriangulateImage(1), 0);
  tri.set_min_angle_deg(0.05);
  EXPECT_EQ(tri.TriangulateImage(1), kPoints);
}

TEST(IncrementalTriangulator, SkipsTracksOfTwoViewsOnly) {
  // Two separate pairs: every keypoint's track has two views, nothing is created unless asked.
  Views v = MakeViews({{1, 2}, {3, 4}});
  const CorrespondenceGraph graph(v.num_kp, v.pairs);
  EXPECT_TRUE(graph.IsTwoViewObservation(1, 5));
  IncrementalTriangulator tri(graph, &v.rec, {});
  EXPECT_EQ(tri.TriangulateImage(1), 0);
  EXPECT_EQ(tri.TriangulateImage(3), 0);
  TriangulatorOptions keep;
  keep.ignore_two_view_tracks = false;
  IncrementalTriangulator tri_keep(graph, &v.rec, keep);
  EXPECT_EQ(tri_keep.TriangulateImage(1), kPoints);
  // A chain 1–2–3: image 1's keypoints have one correspondence, but image 2's have two — a three-view track.
  Views chain = MakeViews({{1, 2}, {2, 3}});
  const CorrespondenceGraph chain_graph(chain.num_kp, chain.pairs);
  EXPECT_FALSE(chain_graph.IsTwoViewObservation(1, 5));
  IncrementalTriangulator tri_chain(chain_graph, &chain.rec, {});
  EXPECT_EQ(tri_chain.TriangulateImage(1), kPoints);
  for (const auto& [pid, p] : chain.rec.points) EXPECT_EQ(p.track.size(), 3u);
}

TEST(MapperPrimitives, FilterDropsBadObservationsAndNarrowPoints) {
  Views v = MakeViews({{1, 2}, {2, 3}, {3, 4}});
  const CorrespondenceGraph graph(v.num_kp, v.pairs);
  IncrementalTriangulator tri(graph, &v.rec, {});
  ASSERT_EQ(tri.TriangulateImage(1), kPoints);
  // Move keypoint 0 of image 4 by 10 px: that observation goes, its point stays (3 observations left).
  v.rec.images.at(4).points2d[0] += Eigen::Vector2d(10, 0);
  PointFilterOptions fo;
  EXPECT_EQ(FilterPoints(&v.rec, nullptr, fo), 0);
  const int64_t pid0 = v.rec.images.at(1).point3d_ids[0];
  EXPECT_EQ(v.rec.points.at(static_cast<uint64_t>(pid0)).track.size(), 3u);
  EXPECT_EQ(v.rec.images.at(4).point3d_ids[0], core::kNoPoint3D);
  // Demanding more parallax than the 40° arc offers deletes every point.
  fo.min_angle_deg = 60;
  EXPECT_EQ(FilterPoints(&v.rec, nullptr, fo), kPoints);
  EXPECT_TRUE(v.rec.points.empty());
  for (const auto& [id, im] : v.rec.images)
    for (int64_t pid : im.point3d_ids) EXPECT_EQ(pid, core::kNoPoint3D);
}

}  // namespace
}  // namespace fmv3d::sfm
