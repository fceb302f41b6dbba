// Track completion by projection on exact synthetic views: which keypoints join a track (near the projection,
// free, looking like the track) and which do not, with exact counts.
#include "fmv3d/sfm/guided_completion.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::sfm {
namespace {

constexpr int kPoints = 60;

// Four cameras on an arc 10 m from 60 points. Every point is triangulated and observed in images 1 and 2
// (keypoint k = point k, exact projections, descriptors = the point's own descriptor + a little noise).
// Images 3 and 4 are registered with no observations; their keypoints are set by each test.
struct Scene {
  core::Reconstruction rec;
  std::vector<Eigen::Vector3d> X;
  std::map<uint32_t, features::Descriptors> desc;
  std::vector<std::array<uint8_t, 128>> base;  // each point's own descriptor
  std::mt19937 rng{7};

  Scene() {
    rec.cameras[1] = core::Camera::Pinhole(1000, 800, 900);
    std::uniform_int_distribution<int> value(0, 60);
    for (int k = 0; k < kPoints; ++k) {
      X.emplace_back(2 * std::sin(1.3 * k), 2 * std::cos(0.7 * k), std::sin(2.1 * k));
      std::array<uint8_t, 128> b;
      for (auto& v : b) v = static_cast<uint8_t>(value(rng));
      base.push_back(b);
    }
    for (uint32_t id = 1; id <= 4; ++id) {
      const double a = 40 * M_PI / 180 * (static_cast<double>(id) - 2.5) / 3;
      core::Image im;
      im.id = id;
      im.camera_id = 1;
      im.name = std::to_string(id);
      im.pose = core::Pose::LookAt(Eigen::Vector3d(10 * std::sin(a), -10 * std::cos(a), 1), Eigen::Vector3d::Zero());
      rec.images[id] = im;
      desc[id] = features::Descriptors(0, 128);
    }
    for (int k = 0; k < kPoints; ++k) {
      core::Point3D p;
      p.id = k + 1;
      p.xyz = X[k];
      for (uint32_t id : {1u, 2u}) {
        p.track.push_back({id, AddKeypoint(id, Projection(id, k), Noisy(k))});
        rec.images[id].point3d_ids.back() = p.id;
      }
      rec.points[p.id] = p;
    }
  }
  Eigen::Vector2d Projection(uint32_t id, int k) const {
    return rec.cameras.at(1).Project(rec.images.at(id).pose.Transform(X[k]));
  }
  std::array<uint8_t, 128> Noisy(int k) {
    std::uniform_int_distribution<int> noise(-3, 3);
    std::array<uint8_t, 128> d = base[k];
    for (auto& v : d) v = static_cast<uint8_t>(std::clamp(int(v) + noise(rng), 0, 255));
    return d;
  }
  // The descriptor point k has in image 1 (a candidate that looks exactly like a member: always within the bound).
  std::array<uint8_t, 128> Member(int k) const {
    std::array<uint8_t, 128> d;
    const core::TrackElement& t = rec.points.at(k + 1).track[0];
    for (int c = 0; c < 128; ++c) d[c] = desc.at(t.image_id)(t.point2d_idx, c);
    return d;
  }
  // A descriptor unlike any point's (values the points' descriptors never take).
  std::array<uint8_t, 128> Unrelated() {
    std::uniform_int_distribution<int> value(120, 200);
    std::array<uint8_t, 128> d;
    for (auto& v : d) v = static_cast<uint8_t>(value(rng));
    return d;
  }
  uint32_t AddKeypoint(uint32_t id, const Eigen::Vector2d& uv, const std::array<uint8_t, 128>& d) {
    core::Image& im = rec.images[id];
    im.points2d.push_back(uv);
    im.point3d_ids.push_back(core::kNoPoint3D);
    features::Descriptors& D = desc[id];
    D.conservativeResize(D.rows() + 1, 128);
    for (int c = 0; c < 128; ++c) D(D.rows() - 1, c) = d[c];
    return static_cast<uint32_t>(im.points2d.size() - 1);
  }
  std::map<uint32_t, const features::Descriptors*> Descriptors() const {
    std::map<uint32_t, const features::Descriptors*> out;
    for (const auto& [id, d] : desc) out[id] = &d;
    return out;
  }
  static std::map<uint32_t, std::set<uint32_t>> AllCovisible() {
    std::map<uint32_t, std::set<uint32_t>> c;
    for (uint32_t a = 1; a <= 4; ++a)
      for (uint32_t b = 1; b <= 4; ++b)
        if (a != b) c[a].insert(b);
    return c;
  }
};

// Keypoints of chance in images 3 and 4, every 5 px outside the part of the image the points project into:
// where the decoy searches (half an image away from each projection) look. Their descriptors are drawn like the
// points' own, so the bound is measured against keypoints as alike as any chance keypoint can be.
void AddChanceKeypoints(Scene* s) {
  for (uint32_t id : {3u, 4u})
    for (int y = 2; y < 800; y += 5)
      for (int x = 2; x < 1000; x += 5)
        if (x < 250 || x > 750 || y < 150 || y > 650) {
          std::array<uint8_t, 128> d;
          std::uniform_int_distribution<int> value(0, 60);
          for (auto& v : d) v = static_cast<uint8_t>(value(s->rng));
          s->AddKeypoint(id, Eigen::Vector2d(x, y), d);
        }
}

GuidedCompletionOptions SmallSceneOptions() {
  GuidedCompletionOptions o;
  o.min_decoys_for_bound = 50;
  return o;
}

TEST(GuidedCompletion, KeypointsNearTheProjectionThatLookLikeTheTrackJoinIt) {
  Scene s;
  AddChanceKeypoints(&s);
  std::vector<uint32_t> true_kp3(kPoints);
  std::vector<int64_t> expect4(kPoints, -1);  // the keypoint of image 4 point k should gain, or -1
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(0, 2 * M_PI);
  auto offset = [&](double r) {
    const double a = angle(rng);
    return Eigen::Vector2d(r * std::cos(a), r * std::sin(a));
  };
  for (int k = 0; k < kPoints; ++k) {
    // Image 3: the point's keypoint 1 px off its projection, and for every fifth point an unrelated keypoint
    // nearer still (0.5 px) that must not be taken.
    true_kp3[k] = s.AddKeypoint(3, s.Projection(3, k) + offset(1.0), s.Member(k));
    if (k % 5 == 0) s.AddKeypoint(3, s.Projection(3, k) + offset(0.5), s.Unrelated());
    // Image 4: the keypoint 6 px away (outside the 4 px radius); only an unrelated keypoint near; or the
    // point's keypoint, but already observing another point; else the point's keypoint 2 px away.
    if (k % 4 == 0) {
      s.AddKeypoint(4, s.Projection(4, k) + offset(6.0), s.Member(k));
    } else if (k % 4 == 1) {
      s.AddKeypoint(4, s.Projection(4, k) + offset(2.0), s.Unrelated());
    } else if (k % 7 == 3) {
      const uint32_t kp = s.AddKeypoint(4, s.Projection(4, k) + offset(2.0), s.Member(k));
      // Held by a point behind every camera (it cannot claim anything itself).
      core::Point3D other;
      other.id = 1000 + k;
      other.xyz = Eigen::Vector3d(0, -20, 0);
      other.track.push_back({4, kp});
      s.rec.images[4].point3d_ids[kp] = static_cast<int64_t>(other.id);
      s.rec.points[other.id] = other;
    } else {
      expect4[k] = s.AddKeypoint(4, s.Projection(4, k) + offset(2.0), s.Member(k));
    }
  }
  const size_t preassigned = [&] {
    size_t n = 0;
    for (int64_t id : s.rec.images[4].point3d_ids) n += id != core::kNoPoint3D;
    return n;
  }();
  ASSERT_GT(preassigned, 0u);
  const GuidedCompletionStats st =
      CompleteTracksByProjection(&s.rec, s.Descriptors(), Scene::AllCovisible(), SmallSceneOptions());
  size_t expected4 = 0;
  for (int64_t e : expect4) expected4 += e >= 0;
  EXPECT_EQ(st.accepted, kPoints + expected4);
  EXPECT_GT(st.descriptor_bound, 0);
  for (int k = 0; k < kPoints; ++k) {
    const core::Point3D& p = s.rec.points.at(k + 1);
    std::map<uint32_t, uint32_t> by_image;
    for (const auto& t : p.track) {
      EXPECT_FALSE(by_image.count(t.image_id)) << "point " << k << " holds image " << t.image_id << " twice";
      by_image[t.image_id] = t.point2d_idx;
      EXPECT_EQ(s.rec.images.at(t.image_id).point3d_ids[t.point2d_idx], static_cast<int64_t>(p.id));
    }
    ASSERT_TRUE(by_image.count(3)) << "point " << k;
    EXPECT_EQ(by_image[3], true_kp3[k]) << "point " << k;
    // Image 4: only the expected keypoint (points that held a pre-assigned one keep exactly that one).
    if (expect4[k] >= 0) {
      ASSERT_TRUE(by_image.count(4)) << "point " << k;
      EXPECT_EQ(by_image[4], static_cast<uint32_t>(expect4[k])) << "point " << k;
    }
  }
  size_t held4 = 0;
  for (int64_t id : s.rec.images[4].point3d_ids) held4 += id != core::kNoPoint3D;
  EXPECT_EQ(held4, preassigned + expected4);
}

TEST(GuidedCompletion, OnlyCovisibleImagesAreSearched) {
  Scene s;
  AddChanceKeypoints(&s);
  for (int k = 0; k < kPoints; ++k) {
    s.AddKeypoint(3, s.Projection(3, k), s.Member(k));
    s.AddKeypoint(4, s.Projection(4, k), s.Member(k));
  }
  // Image 4 shares no verified pair with images 1 or 2.
  std::map<uint32_t, std::set<uint32_t>> covisible = {{1, {2, 3}}, {2, {1, 3}}, {3, {1, 2}}};
  const GuidedCompletionStats st = CompleteTracksByProjection(&s.rec, s.Descriptors(), covisible, SmallSceneOptions());
  EXPECT_EQ(st.accepted, static_cast<size_t>(kPoints));
  for (const auto& [pid, p] : s.rec.points) {
    ASSERT_EQ(p.track.size(), 3u);
    EXPECT_EQ(p.track.back().image_id, 3u);
  }
}

TEST(GuidedCompletion, TooFewDecoysToMeasureTheBoundAddsNothing) {
  Scene s;
  for (int k = 0; k < kPoints; ++k) s.AddKeypoint(3, s.Projection(3, k), s.Member(k));
  GuidedCompletionOptions o;
  o.min_decoys_for_bound = 1000;
  const GuidedCompletionStats st = CompleteTracksByProjection(&s.rec, s.Descriptors(), Scene::AllCovisible(), o);
  EXPECT_EQ(st.accepted, 0u);
  EXPECT_LT(st.decoys, 1000u);
  EXPECT_EQ(st.member_distances, static_cast<size_t>(2 * kPoints));
  for (const auto& [pid, p] : s.rec.points) EXPECT_EQ(p.track.size(), 2u);
}

TEST(GuidedCompletion, DescriptorCountMustMatchTheKeypoints) {
  Scene s;
  s.desc[2].conservativeResize(s.desc[2].rows() - 1, 128);
  EXPECT_THROW(CompleteTracksByProjection(&s.rec, s.Descriptors(), Scene::AllCovisible(), SmallSceneOptions()), Error);
}

}  // namespace
}  // namespace fmv3d::sfm
