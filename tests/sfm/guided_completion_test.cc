// Track completion by projection on synthetic views with known keypoint noise: which keypoints join a track
// (inside the search region the noise and the point's uncertainty set, free, looking like the track) and which do
// not, with exact counts; the noise model by keypoint scale; additions the adjusted model does not explain.
#include "fmv3d/sfm/guided_completion.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::sfm {
namespace {

constexpr int kPoints = 60;

constexpr double kNoisePx = 0.15;  // keypoint noise per axis of the observations in images 1 and 2

// Four cameras on an arc 10 m from 60 points. Every point is triangulated and observed in images 1 and 2
// (keypoint k = point k, projections + Gaussian noise, descriptors = the point's own descriptor + a little noise).
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
      std::normal_distribution<double> px(0, kNoisePx);
      for (uint32_t id : {1u, 2u}) {
        const Eigen::Vector2d noise{px(rng), px(rng)};
        p.track.push_back({id, AddKeypoint(id, Projection(id, k) + noise, Noisy(k))});
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
    AddKeypoints(id, {uv}, {d});
    return static_cast<uint32_t>(rec.images[id].points2d.size() - 1);
  }
  // One resize for many keypoints: a resize per keypoint copies the whole matrix each time (quadratic).
  void AddKeypoints(uint32_t id, const std::vector<Eigen::Vector2d>& uv,
                    const std::vector<std::array<uint8_t, 128>>& d) {
    core::Image& im = rec.images[id];
    features::Descriptors& D = desc[id];
    const Eigen::Index first = D.rows();
    D.conservativeResize(first + static_cast<Eigen::Index>(uv.size()), 128);
    for (size_t i = 0; i < uv.size(); ++i) {
      im.points2d.push_back(uv[i]);
      im.point3d_ids.push_back(core::kNoPoint3D);
      for (int c = 0; c < 128; ++c) D(first + static_cast<Eigen::Index>(i), c) = d[i][c];
    }
  }
  // The offset at `fraction` of the boundary of point k's search region in image id (keypoints without scales,
  // default search mass), in direction `angle`.
  Eigen::Vector2d RegionOffset(uint32_t id, int k, double fraction, double angle) const {
    const KeypointNoise noise(rec, {}, 1);
    const double sigma = noise.overall();
    const Eigen::Matrix2d S =
        ProjectedPointCovariance(rec, rec.points.at(k + 1), id, noise) + sigma * sigma * Eigen::Matrix2d::Identity();
    const Eigen::Vector2d d(std::cos(angle), std::sin(angle));
    const double chi2 = -2 * std::log(1 - GuidedCompletionOptions().search_mass);
    return fraction * std::sqrt(chi2 / d.dot(S.inverse() * d)) * d;
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
  for (uint32_t id : {3u, 4u}) {
    std::vector<Eigen::Vector2d> uv;
    std::vector<std::array<uint8_t, 128>> desc;
    for (int y = 2; y < 800; y += 5)
      for (int x = 2; x < 1000; x += 5)
        if (x < 250 || x > 750 || y < 150 || y > 650) {
          std::array<uint8_t, 128> d;
          std::uniform_int_distribution<int> value(0, 60);
          for (auto& v : d) v = static_cast<uint8_t>(value(s->rng));
          uv.emplace_back(x, y);
          desc.push_back(d);
        }
    s->AddKeypoints(id, uv, desc);
  }
}

GuidedCompletionOptions SmallSceneOptions() {
  GuidedCompletionOptions o;
  o.min_decoys_for_bound = 50;
  return o;
}

TEST(GuidedCompletion, SearchRegionFollowsTheKeypointNoise) {
  Scene s;
  const KeypointNoise noise(s.rec, {}, 1);
  // Residuals of exact points (not fitted), scaled up for the degrees of freedom a fit would have taken.
  EXPECT_GT(noise.overall(), kNoisePx);
  EXPECT_LT(noise.overall(), 4 * kNoisePx);
  // The region is at least 3.44 σ wide (the point's own uncertainty widens it: two views 13° apart leave the depth
  // loose) and, for the points the two views determine well, well inside the 4 px cap.
  int inside_cap = 0;
  for (int k = 0; k < kPoints; ++k)
    for (uint32_t id : {3u, 4u})
      for (double a : {0.0, M_PI / 2}) {
        const double boundary = s.RegionOffset(id, k, 1.0, a).norm();
        EXPECT_GT(boundary, 3.4 * noise.overall()) << "point " << k;
        inside_cap += 1.5 * boundary < GuidedCompletionOptions().max_error_px;
      }
  EXPECT_GE(inside_cap, 4 * kPoints / 3);
}

TEST(GuidedCompletion, KeypointsInsideTheSearchRegionThatLookLikeTheTrackJoinIt) {
  Scene s;
  AddChanceKeypoints(&s);
  std::vector<uint32_t> true_kp3(kPoints);
  std::vector<int64_t> expect4(kPoints, -1);  // the keypoint of image 4 point k should gain, or -1
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(0, 2 * M_PI);
  auto at = [&](uint32_t id, int k, double fraction) -> Eigen::Vector2d {
    return s.Projection(id, k) + s.RegionOffset(id, k, fraction, angle(rng));
  };
  const double cap = GuidedCompletionOptions().max_error_px;
  int beyond_region_in_cap = 0;
  for (int k = 0; k < kPoints; ++k) {
    // Image 3: the point's keypoint halfway to the region's boundary, and for every fifth point an unrelated
    // keypoint nearer still that must not be taken.
    true_kp3[k] = s.AddKeypoint(3, at(3, k, 0.5), s.Member(k));
    if (k % 5 == 0) s.AddKeypoint(3, at(3, k, 0.25), s.Unrelated());
    // Image 4: a keypoint exactly like the track's beyond the region's boundary (inside the 4 px cap where the
    // region leaves room, else beyond it): what repeated texture puts near a projection; only an unrelated keypoint
    // near; or the point's keypoint, but already observing another point; else the point's keypoint inside the region.
    if (k % 4 == 0) {
      const double a = angle(rng), boundary = s.RegionOffset(4, k, 1.0, a).norm();
      const bool in_cap = boundary < 0.9 * cap;
      beyond_region_in_cap += in_cap;
      const double fraction = in_cap ? std::min(1.4, 0.5 * (1 + cap / boundary)) : 1.5 * cap / boundary;
      s.AddKeypoint(4, s.Projection(4, k) + s.RegionOffset(4, k, fraction, a), s.Member(k));
    } else if (k % 4 == 1) {
      s.AddKeypoint(4, at(4, k, 0.5), s.Unrelated());
    } else if (k % 7 == 3) {
      const uint32_t kp = s.AddKeypoint(4, at(4, k, 0.5), s.Member(k));
      // Held by a point behind every camera (it cannot claim anything itself).
      core::Point3D other;
      other.id = 1000 + k;
      other.xyz = Eigen::Vector3d(0, -20, 0);
      other.track.push_back({4, kp});
      s.rec.images[4].point3d_ids[kp] = static_cast<int64_t>(other.id);
      s.rec.points[other.id] = other;
    } else {
      expect4[k] = s.AddKeypoint(4, at(4, k, 0.8), s.Member(k));
    }
  }
  const size_t preassigned = [&] {
    size_t n = 0;
    for (int64_t id : s.rec.images[4].point3d_ids) n += id != core::kNoPoint3D;
    return n;
  }();
  ASSERT_GT(preassigned, 0u);
  ASSERT_GE(beyond_region_in_cap, 5);
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

// Every point's keypoint in image 3 halfway to its region's boundary, a noisy copy of the track's descriptor; for
// every other point a rival as like the track on the other side, outside the region but inside the cap (where the
// region reaches the cap, none). Returns the keypoints and whether each point has a rival.
std::pair<std::vector<uint32_t>, std::vector<bool>> AddKeypointsWithRivals(Scene* s) {
  std::vector<uint32_t> kp(kPoints);
  std::vector<bool> rival(kPoints, false);
  const double cap = GuidedCompletionOptions().max_error_px;
  for (int k = 0; k < kPoints; ++k) {
    kp[k] = s->AddKeypoint(3, s->Projection(3, k) + s->RegionOffset(3, k, 0.5, 0.3 * k), s->Noisy(k));
    const double boundary = s->RegionOffset(3, k, 1.0, 0.3 * k + M_PI).norm();
    if (k % 2 == 0 && boundary < 0.9 * cap) {
      const double fraction = std::min(1.5, 0.5 * (1 + cap / boundary));
      s->AddKeypoint(3, s->Projection(3, k) + s->RegionOffset(3, k, fraction, 0.3 * k + M_PI), s->Noisy(k));
      rival[k] = true;
    }
  }
  return {kp, rival};
}

TEST(GuidedCompletion, ARivalThatLooksAsMuchLikeTheTrackLeavesTheChoiceOpen) {
  Scene s;
  AddChanceKeypoints(&s);
  const auto [kp3, rival] = AddKeypointsWithRivals(&s);
  const size_t rivals = std::count(rival.begin(), rival.end(), true);
  ASSERT_GE(rivals, static_cast<size_t>(kPoints / 3));
  const GuidedCompletionStats st =
      CompleteTracksByProjection(&s.rec, s.Descriptors(), Scene::AllCovisible(), SmallSceneOptions());
  EXPECT_EQ(st.accepted, kPoints - rivals);
  EXPECT_EQ(st.ambiguous, rivals);
  for (int k = 0; k < kPoints; ++k)
    EXPECT_EQ(s.rec.images.at(3).point3d_ids[kp3[k]], rival[k] ? core::kNoPoint3D : int64_t{k + 1}) << k;
  // Without the ratio test the region decides alone.
  Scene t;
  AddChanceKeypoints(&t);
  AddKeypointsWithRivals(&t);
  GuidedCompletionOptions o = SmallSceneOptions();
  o.ratio = 1;
  EXPECT_EQ(CompleteTracksByProjection(&t.rec, t.Descriptors(), Scene::AllCovisible(), o).accepted,
            static_cast<size_t>(kPoints));
}

TEST(GuidedCompletion, AdditionsTheModelDoesNotExplainAreRemoved) {
  Scene s;
  std::vector<std::pair<uint64_t, core::TrackElement>> added;
  for (int k = 0; k < kPoints; ++k) {
    // Every third addition 1.2 px off (a keypoint of chance the adjustment could not pull in), the rest 0.3 px.
    const double off = (k % 3 == 0 ? 4.0 : 1.0) * kNoisePx * 2;
    const uint32_t kp = s.AddKeypoint(3, s.Projection(3, k) + Eigen::Vector2d(off, 0), s.Member(k));
    s.rec.images[3].point3d_ids[kp] = k + 1;
    s.rec.points.at(k + 1).track.push_back({3, kp});
    added.push_back({static_cast<uint64_t>(k + 1), {3, kp}});
  }
  const double sigma = KeypointNoise(s.rec, {}, 1).overall();
  ASSERT_GT(4 * 2 * kNoisePx, 3.44 * sigma);
  ASSERT_LT(1 * 2 * kNoisePx, 3.44 * sigma);
  EXPECT_EQ(RemoveAdditionsThatDoNotFit(&s.rec, added, GuidedCompletionOptions()), static_cast<size_t>(kPoints / 3));
  for (int k = 0; k < kPoints; ++k) {
    const core::Point3D& p = s.rec.points.at(k + 1);
    EXPECT_EQ(p.track.size(), k % 3 == 0 ? 2u : 3u) << k;
    EXPECT_EQ(s.rec.images.at(3).point3d_ids[added[k].second.point2d_idx],
              k % 3 == 0 ? core::kNoPoint3D : int64_t{k + 1});
  }
}

TEST(GuidedCompletion, LargerKeypointsAreNoisier) {
  // Images 1 and 2 again, their keypoints given scales: the first half small (1.2 px) and exact to 0.05 px, the
  // second large (8 px) and off by 0.5 px.
  Scene s;
  std::mt19937 rng(11);
  std::normal_distribution<double> px(0, 1);
  std::map<uint32_t, std::vector<float>> scales;
  for (uint32_t id : {1u, 2u}) {
    core::Image& im = s.rec.images[id];
    for (size_t k = 0; k < im.points2d.size(); ++k) {
      const bool large = k >= im.points2d.size() / 2;
      scales[id].push_back(large ? 8.0f : 1.2f);
      im.points2d[k] = s.Projection(id, static_cast<int>(k)) + (large ? 0.5 : 0.05) * Eigen::Vector2d{px(rng), px(rng)};
    }
  }
  const KeypointScales by_image = {{1, &scales[1]}, {2, &scales[2]}};
  const KeypointNoise noise(s.rec, by_image, 20);
  const double small = noise.Sigma(1, 0), large = noise.Sigma(1, kPoints - 1);
  EXPECT_GT(large / small, 5);
  EXPECT_EQ(KeypointNoise::Bin(1.2f), KeypointNoise::Bin(1.3f));
  EXPECT_NE(KeypointNoise::Bin(1.2f), KeypointNoise::Bin(8.0f));
  // An image without scales takes the noise of all observations, between the two.
  const double all = noise.Sigma(3, 0);
  EXPECT_GT(all, small);
  EXPECT_LT(all, large);
  // Too few observations per bin: every keypoint takes that overall noise.
  EXPECT_DOUBLE_EQ(KeypointNoise(s.rec, by_image, 1000).Sigma(1, 0), all);
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
