// Relocalisation of left-out images against a model, and guided (epipolar) matching, on synthetic nadir views of
// rolling ground with exact poses and per-point descriptors.
#include "fmv3d/sfm/relocalise.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/features/matcher.h"

namespace fmv3d::sfm {
namespace {

using Desc = Eigen::Matrix<uint8_t, 1, 128>;

Desc RandomDescriptor(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  Eigen::Matrix<double, 1, 128> v;
  for (int k = 0; k < 128; ++k) v[k] = u(rng) * u(rng);
  v *= 512 / v.norm();
  Desc d;
  for (int k = 0; k < 128; ++k) d[k] = static_cast<uint8_t>(std::min(255.0, std::round(v[k])));
  return d;
}

Desc Perturb(const Desc& d, std::mt19937_64& rng, double sigma) {
  std::normal_distribution<double> g(0, sigma);
  Desc o;
  for (int k = 0; k < 128; ++k) o[k] = static_cast<uint8_t>(std::clamp(std::round(d[k] + g(rng)), 0.0, 255.0));
  return o;
}

// Ground points on gentle relief seen by a 3 x 4 nadir grid; `shared_descriptors`: every descriptor is used by
// two points far apart (a repetitive, low-texture surface: a global ratio test cannot tell them apart).
struct World {
  core::Camera camera;
  std::vector<core::Pose> poses;
  std::vector<Eigen::Vector3d> X;
  std::vector<Desc> point_desc;
  std::vector<features::FeatureSet> feats;  // per image
  std::vector<std::vector<int>> point_of;   // per image, per keypoint: the point (-1: clutter)
};

World MakeWorld(bool shared_descriptors, uint64_t seed = 3) {
  World w;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> g(0, 0.3);
  w.camera = core::Camera::Pinhole(1200, 800, 1000);
  w.camera.id = 1;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) {
      const Eigen::Vector3d centre(c * 25.0, r * 40.0, 100 + u(rng));
      Eigen::Matrix3d Rwc;  // camera x east, y south, z down
      Rwc << 1, 0, 0, 0, -1, 0, 0, 0, -1;
      const Eigen::Matrix3d jitter =
          Eigen::AngleAxisd{0.01 * u(rng), Eigen::Vector3d{u(rng), u(rng), 1}.normalized()}.toRotationMatrix();
      w.poses.push_back(core::Pose::FromRotationAndCentre(jitter * Rwc.transpose(), centre));
    }
  const int num_points = 6000;
  for (int i = 0; i < num_points; ++i) {
    const double x = -40 + 155 * (u(rng) + 1) / 2, y = -35 + 150 * (u(rng) + 1) / 2;
    w.X.emplace_back(x, y, 4 * std::sin(x / 20) * std::cos(y / 25));
    if (shared_descriptors && i % 2 == 1)
      w.point_desc.push_back(w.point_desc.back());
    else
      w.point_desc.push_back(RandomDescriptor(rng));
  }
  for (size_t c = 0; c < w.poses.size(); ++c) {
    features::FeatureSet f;
    f.width = w.camera.width, f.height = w.camera.height;
    std::vector<Desc> rows;
    std::vector<int> pof;
    for (int i = 0; i < num_points; ++i) {
      const Eigen::Vector3d xc = w.poses[c].Transform(w.X[i]);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = w.camera.Project(xc) + Eigen::Vector2d{g(rng), g(rng)};
      if (!w.camera.InImage(uv, 2)) continue;
      f.keypoints.push_back({static_cast<float>(uv.x()), static_cast<float>(uv.y()), 2, 0});
      rows.push_back(Perturb(w.point_desc[i], rng, 4));
      pof.push_back(i);
    }
    for (int k = 0; k < 300; ++k) {  // clutter
      f.keypoints.push_back({static_cast<float>(600 + 590 * u(rng)), static_cast<float>(400 + 390 * u(rng)), 2, 0});
      rows.push_back(RandomDescriptor(rng));
      pof.push_back(-1);
    }
    f.descriptors.resize(static_cast<Eigen::Index>(rows.size()), 128);
    for (size_t r = 0; r < rows.size(); ++r) f.descriptors.row(static_cast<Eigen::Index>(r)) = rows[r];
    f.colors.assign(rows.size(), Eigen::Matrix<uint8_t, 3, 1>(1, 2, 3));
    w.feats.push_back(std::move(f));
    w.point_of.push_back(std::move(pof));
  }
  return w;
}

// The model: every image except `left_out` at its true pose, every point seen by ≥ 2 of them triangulated
// exactly, except points with index % untriangulated_every == 0 (when > 0).
core::Reconstruction MakeModel(const World& w, const std::set<uint32_t>& left_out, int untriangulated_every) {
  core::Reconstruction rec;
  rec.cameras[1] = w.camera;
  for (size_t c = 0; c < w.poses.size(); ++c) {
    const uint32_t id = static_cast<uint32_t>(c + 1);
    if (left_out.count(id)) continue;
    core::Image im;
    im.id = id;
    im.camera_id = 1;
    im.name = "img" + std::to_string(id);
    im.pose = w.poses[c];
    for (const auto& k : w.feats[c].keypoints) im.points2d.emplace_back(k.x, k.y);
    im.point3d_ids.assign(im.points2d.size(), core::kNoPoint3D);
    rec.images[id] = im;
  }
  std::map<int, std::vector<core::TrackElement>> tracks;
  for (const auto& [id, im] : rec.images)
    for (size_t k = 0; k < w.point_of[id - 1].size(); ++k) {
      const int p = w.point_of[id - 1][k];
      if (p >= 0 && !(untriangulated_every > 0 && p % untriangulated_every == 0))
        tracks[p].push_back({id, static_cast<uint32_t>(k)});
    }
  for (const auto& [p, track] : tracks) {
    if (track.size() < 2) continue;
    core::Point3D pt;
    pt.id = static_cast<uint64_t>(p) + 1;
    pt.xyz = w.X[p];
    pt.track = track;
    for (const auto& el : track) rec.images.at(el.image_id).point3d_ids[el.point2d_idx] = static_cast<int64_t>(pt.id);
    rec.points[pt.id] = pt;
  }
  return rec;
}

std::map<uint32_t, const features::FeatureSet*> FeatureMap(const World& w) {
  std::map<uint32_t, const features::FeatureSet*> m;
  for (size_t c = 0; c < w.feats.size(); ++c) m[static_cast<uint32_t>(c + 1)] = &w.feats[c];
  return m;
}

TEST(Relocalise, RegistersLeftOutImagesAndTriangulatesWithTheirNeighbours) {
  const World w = MakeWorld(false);
  core::Reconstruction rec = MakeModel(w, {6, 7}, 3);  // two inner images left out; a third of the points open
  const size_t points_before = rec.points.size();
  std::set<uint64_t> old_ids;
  for (const auto& [pid, p] : rec.points) old_ids.insert(pid);
  std::vector<RelocaliseCandidate> cands = {{6, 1, "img6"}, {7, 1, "img7"}};
  const auto st = RelocaliseImages(&rec, cands, FeatureMap(w), {{1, w.camera}}, RelocaliseOptions{});
  ASSERT_EQ(st.registered.size(), 2u);
  EXPECT_TRUE(st.still_failed.empty());
  for (uint32_t id : {6u, 7u}) {
    ASSERT_TRUE(rec.images.count(id));
    const auto& pose = rec.images.at(id).pose;
    EXPECT_LT((pose.Centre() - w.poses[id - 1].Centre()).norm(), 0.05) << id;
    EXPECT_LT(Eigen::AngleAxisd(pose.q * w.poses[id - 1].q.conjugate()).angle() * 180 / M_PI, 0.02) << id;
  }
  // Guided matching triangulated the open points the new images share with their neighbours, correctly.
  EXPECT_GT(st.points_added, 500);
  EXPECT_GT(rec.points.size(), points_before);
  int checked = 0, wrong = 0;
  for (const auto& [pid, p] : rec.points) {
    if (old_ids.count(pid)) continue;
    const auto& el = p.track[0];
    const int truth = w.point_of[el.image_id - 1][el.point2d_idx];
    ++checked;
    wrong += truth < 0 || (p.xyz - w.X[truth]).norm() > 0.5;
  }
  EXPECT_GT(checked, 0);
  EXPECT_LE(wrong, checked / 100) << wrong << " of " << checked;
  rec.Validate();
}

TEST(Relocalise, ImageOfSomewhereElseStaysOut) {
  World w = MakeWorld(false);
  std::mt19937_64 rng(9);
  for (Eigen::Index r = 0; r < w.feats[5].descriptors.rows(); ++r)
    w.feats[5].descriptors.row(r) = RandomDescriptor(rng);
  core::Reconstruction rec = MakeModel(w, {6}, 0);
  const auto st = RelocaliseImages(&rec, {{6, 1, "img6"}}, FeatureMap(w), {{1, w.camera}}, RelocaliseOptions{});
  EXPECT_TRUE(st.registered.empty());
  ASSERT_TRUE(st.still_failed.count(6));
  EXPECT_FALSE(rec.images.count(6));
}

TEST(Relocalise, MissingFeaturesIsAnError) {
  const World w = MakeWorld(false);
  core::Reconstruction rec = MakeModel(w, {6}, 0);
  auto feats = FeatureMap(w);
  feats.erase(6);
  EXPECT_THROW(RelocaliseImages(&rec, {{6, 1, "img6"}}, feats, {{1, w.camera}}, RelocaliseOptions{}), Error);
}

TEST(GuidedMatches, FindsRepetitiveMatchesThatAGlobalRatioTestRejects) {
  const World w = MakeWorld(true);
  core::Reconstruction rec = MakeModel(w, {}, 1);  // all images registered, no point triangulated
  ASSERT_TRUE(rec.points.empty());
  // Global matching with the ratio test: the twin descriptors make nearly every true match ambiguous.
  features::ImageDescriptors a(w.feats[5].descriptors, 6), b(w.feats[6].descriptors, 7);
  features::MatchOptions mo;
  const auto global = features::MatchDescriptors(a, b, mo);
  const auto guided = GuidedMatches(rec, 6, 7, w.feats[5], w.feats[6], 90, 115, 3, 0.9);
  int correct = 0;
  for (const auto& m : guided) {
    const int pa = w.point_of[5][m.idx1], pb = w.point_of[6][m.idx2];
    correct += pa >= 0 && pa == pb;
  }
  int shared = 0;
  std::set<int> in_b(w.point_of[6].begin(), w.point_of[6].end());
  for (int p : w.point_of[5]) shared += p >= 0 && in_b.count(p);
  std::printf("shared %d, global %zu, guided %zu (%d correct)\n", shared, global.size(), guided.size(), correct);
  EXPECT_LT(global.size(), 0.6 * shared);
  EXPECT_GT(correct, 0.9 * shared);
  EXPECT_GE(correct, static_cast<int>(0.99 * guided.size()));
}

}  // namespace
}  // namespace fmv3d::sfm
