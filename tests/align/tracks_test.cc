// Track alignment and merging on synthetic workspaces whose similarity is known exactly: one world of 3D
// points with one descriptor each, seen by two camera rings; each track's model lives in its own frame.
#include <gtest/gtest.h>

#include <random>

#include "fmv3d/align/merge.h"
#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/colmap_model.h"
#include "test_util.h"

namespace fmv3d::align {
namespace {

namespace fs = std::filesystem;

struct World {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<uint8_t, 128>> descriptors;
  World(uint64_t seed, int n = 800) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    std::uniform_int_distribution<int> d(0, 60);
    for (int i = 0; i < n; ++i) {
      points.push_back({10 * u(rng), 10 * u(rng), 3 + 3 * u(rng)});
      std::array<uint8_t, 128> desc;
      for (auto& v : desc) v = static_cast<uint8_t>(d(rng));
      descriptors.push_back(desc);
    }
  }
};

// Writes WS/sparse (the model in the frame `frame` ∘ world) and WS/features for a ring of cameras.
void WriteTrack(const World& world, const fs::path& ws, const core::Sim3& frame, int cameras, double radius,
                double height, double phase) {
  core::Reconstruction rec;
  rec.cameras[1] = core::Camera::Pinhole(640, 480, 500);
  const core::Camera& cam = rec.cameras[1];
  std::map<size_t, core::Point3D> pts;
  for (int c = 0; c < cameras; ++c) {
    const double a = phase + 2 * M_PI * c / cameras;
    const core::Pose world_pose = core::Pose::LookAt(
        Eigen::Vector3d(radius * std::cos(a), radius * std::sin(a), height), Eigen::Vector3d(0, 0, 3));
    core::Image im;
    im.id = c + 1;
    im.camera_id = 1;
    im.name = "flight-" + std::to_string(100000 + c) + ".png";
    im.pose = frame.Apply(world_pose);
    features::FeatureSet fs_;
    fs_.image_name = im.name;
    fs_.width = cam.width;
    fs_.height = cam.height;
    std::vector<std::array<uint8_t, 128>> rows;
    for (size_t p = 0; p < world.points.size(); ++p) {
      const Eigen::Vector3d xc = world_pose.Transform(world.points[p]);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = cam.Project(xc);
      if (!cam.InImage(uv, 1)) continue;
      const uint32_t idx = static_cast<uint32_t>(im.points2d.size());
      im.points2d.push_back(uv);
      im.point3d_ids.push_back(static_cast<int64_t>(p + 1));
      fs_.keypoints.push_back({float(uv.x()), float(uv.y()), 2.f, 0.f});
      rows.push_back(world.descriptors[p]);
      fs_.colors.push_back(Eigen::Matrix<uint8_t, 3, 1>(128, 128, 128));
      auto& pt = pts[p];
      pt.id = p + 1;
      pt.xyz = frame.Apply(world.points[p]);
      pt.track.push_back({im.id, idx});
    }
    fs_.descriptors.resize(rows.size(), 128);
    for (size_t r = 0; r < rows.size(); ++r)
      for (int k = 0; k < 128; ++k) fs_.descriptors(r, k) = rows[r][k];
    features::WriteFeatures(fs_, features::FeaturePath(ws / "features", im.name));
    rec.images[im.id] = im;
  }
  for (auto& [p, pt] : pts) {
    if (pt.track.size() >= 2) {
      rec.points[pt.id] = pt;
    } else {  // a single view: not triangulated
      for (const auto& el : pt.track) rec.images[el.image_id].point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    }
  }
  io::WriteColmapText(rec, ws / "sparse");
}

core::Sim3 FrameA() {
  core::Sim3 s;
  s.s = 0.5;
  s.q = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 1, 0).normalized());
  s.t = Eigen::Vector3d(3, 1, -2);
  return s;
}
core::Sim3 FrameB() {
  core::Sim3 s;
  s.s = 3.2;
  s.q = Eigen::AngleAxisd(-2.1, Eigen::Vector3d(0.2, -1, 0.4).normalized());
  s.t = Eigen::Vector3d(-40, 7, 12);
  return s;
}

TEST(AlignTracks, RecoversKnownSimilarityAndMerges) {
  test::TempDir dir("fmv3d-tracks");
  const World world(1);
  WriteTrack(world, dir / "A", FrameA(), 10, 30, 15, 0);
  WriteTrack(world, dir / "B", FrameB(), 8, 26, 22, 0.3);
  const nlohmann::json report = RunAlignStage({dir / "A", dir / "B"}, dir / "M", TrackAlignOptions());
  EXPECT_EQ(report.at("reference").get<std::string>(), "A") << "the track with more images";
  const core::Sim3 b_to_a = Sim3FromJson(report.at("tracks")[1].at("to_reference"));
  const core::Sim3 truth = ComposeSim3(FrameA(), FrameB().Inverse());
  EXPECT_NEAR(b_to_a.s / truth.s, 1, 1e-6);
  EXPECT_LT(core::RotationAngle(b_to_a.q, truth.q), 1e-6);
  EXPECT_LT((b_to_a.t - truth.t).norm(), 1e-5);
  EXPECT_GT(report.at("pairs")[0].at("inliers_3d").get<size_t>(), 300u);

  // The merged model: both tracks' images (B's renamed: the names clash), B's points in A's frame.
  const core::Reconstruction merged = io::ReadColmapText(dir / "M/sparse");
  EXPECT_EQ(merged.images.size(), 18u);
  EXPECT_EQ(merged.cameras.size(), 2u);
  EXPECT_NE(merged.FindImageByName("B-flight-100003.png"), nullptr);
  EXPECT_NE(merged.FindImageByName("flight-100003.png"), nullptr);
  const core::Reconstruction a = io::ReadColmapText(dir / "A/sparse");
  const core::Reconstruction b = io::ReadColmapText(dir / "B/sparse");
  // The joint bundle adjustment fused every consistent cross-track link into one point.
  const auto& joint = report.at("joint_bundle_adjustment");
  const size_t fused = joint.at("links_fused").get<size_t>();
  EXPECT_GT(fused, 300u);
  EXPECT_EQ(merged.points.size(), a.points.size() + b.points.size() - fused);
  EXPECT_LT(joint.at("reprojection_rms_after_px").get<double>(), 1e-3);
  // Every merged B camera sits where A's frame puts it.
  for (const auto& [id, im] : b.images) {
    const core::Image* m = merged.FindImageByName("B-" + im.name);
    ASSERT_NE(m, nullptr);
    const Eigen::Vector3d expected = FrameA().Apply(FrameB().Inverse().Apply(im.pose.Centre()));
    EXPECT_LT((m->pose.Centre() - expected).norm(), 1e-5);
  }
  EXPECT_NO_THROW(merged.Validate());
  EXPECT_TRUE(fs::exists(dir / "M/report/align.json"));
}

// A merge from a slightly wrong similarity (0.15°, 0.4% scale, a shift of 0.2% of the scene): the joint
// bundle adjustment over the fused cross-track points pulls B's cameras back onto A's frame.
TEST(AlignTracks, JointBundleAdjustmentCorrectsAnImperfectAlignment) {
  test::TempDir dir("fmv3d-tracks-joint");
  const World world(3);
  WriteTrack(world, dir / "A", FrameA(), 10, 30, 15, 0);
  WriteTrack(world, dir / "B", FrameB(), 8, 26, 22, 0.3);
  const std::vector<Track> tracks = {LoadTrack(dir / "A"), LoadTrack(dir / "B")};
  MultiTrackAlignment alignment = AlignTracks(tracks, TrackAlignOptions());
  ASSERT_EQ(alignment.reference, 0u);
  core::Sim3 error;
  error.s = 1.004;
  error.q = Eigen::AngleAxisd(0.15 * M_PI / 180, Eigen::Vector3d(0.3, 1, 0.2).normalized());
  error.t = Eigen::Vector3d(0.02, -0.01, 0.015) * tracks[0].radius;
  alignment.to_reference[1] = ComposeSim3(error, alignment.to_reference[1]);
  MergedModel merged = MergeTracks(tracks, alignment);

  const core::Reconstruction b = io::ReadColmapText(dir / "B/sparse");
  auto centre_error = [&](const core::Reconstruction& rec) {
    double worst = 0;
    for (const auto& [id, im] : b.images) {
      const core::Image* m = rec.FindImageByName("B-" + im.name);
      const Eigen::Vector3d expected = FrameA().Apply(FrameB().Inverse().Apply(im.pose.Centre()));
      worst = std::max(worst, (m->pose.Centre() - expected).norm() / tracks[0].radius);
    }
    return worst;
  };
  const double before = centre_error(merged.sparse);
  const JointAdjustmentResult r = JointBundleAdjust(&merged, alignment, 10.0);
  const double after = centre_error(merged.sparse);
  EXPECT_GT(r.links_fused, 200u);
  EXPECT_GT(r.rms_before_px, 0.5);
  EXPECT_LT(r.rms_after_px, 0.01);
  EXPECT_GT(before, 5e-3);
  EXPECT_LT(after, 1e-4) << "before " << before;
  EXPECT_NO_THROW(merged.sparse.Validate());
  // B's part of the merged dense cloud would follow the same motion; its recovered correction undoes `error`.
  const core::Sim3 undo = ComposeSim3(r.track_motion[1], error);
  EXPECT_NEAR(undo.s, 1, 1e-4);
  EXPECT_LT(core::RotationAngle(undo.q, Eigen::Quaterniond::Identity()) * 180 / M_PI, 0.005);
}

// Two tracks' dense clouds on one plane, overlapping on 1 <= x <= 2; track 0 was seen from 10 m, track 1
// from 20 m (a coarser footprint): in the overlap only track 0's points stay, elsewhere both tracks' do.
TEST(AlignTracks, KeepFinerInOverlapDropsTheCoarserDuplicates) {
  MergedModel m;
  m.sparse.cameras[1] = core::Camera::Pinhole(640, 480, 500);
  for (uint32_t id : {1u, 2u}) {
    core::Image im;
    im.id = id;
    im.camera_id = 1;
    im.name = std::to_string(id) + ".png";
    im.pose = core::Pose::LookAt(Eigen::Vector3d(1.5, 1, id == 1 ? 10 : 20), Eigen::Vector3d(1.5, 1, 0));
    m.sparse.images[id] = im;
  }
  auto add = [&](double x0, double x1, uint32_t image) {
    const size_t begin = m.dense.size();
    for (double x = x0; x <= x1 + 1e-9; x += 0.05)
      for (double y = 0; y <= 2 + 1e-9; y += 0.05) {
        m.dense.positions.push_back({x, y, 0});
        m.dense.normals.push_back(Eigen::Vector3f::UnitZ());
        m.dense.visibility.push_back({image});
      }
    m.dense_ranges.push_back({begin, m.dense.size()});
  };
  add(0, 2, 1);
  add(1.025, 3.025, 2);  // offset half a spacing: no exact duplicates
  const size_t first = m.dense_ranges[0].second;
  const size_t dropped = KeepFinerInOverlap(&m, 2.0);
  EXPECT_EQ(m.dense_ranges[0].second - m.dense_ranges[0].first, first) << "the finer track keeps every point";
  EXPECT_GT(dropped, 0u);
  for (size_t i = m.dense_ranges[1].first; i < m.dense_ranges[1].second; ++i)
    EXPECT_GT(m.dense.positions[i].x(), 2.0) << "a coarse point in the overlap survived";
  size_t beyond = 0;
  for (const auto& p : m.dense.positions) beyond += p.x() > 2.15;
  EXPECT_EQ(beyond, 18u * 41u) << "the coarse track's own surface (x > 2.15) is kept";
  EXPECT_NO_THROW(m.dense.Validate());
}

TEST(AlignTracks, NoOverlapIsAnErrorAndWritesNothing) {
  test::TempDir dir("fmv3d-tracks-none");
  WriteTrack(World(1), dir / "A", FrameA(), 8, 30, 15, 0);
  WriteTrack(World(2), dir / "B", FrameB(), 8, 26, 22, 0.3);  // another world: nothing in common
  try {
    RunAlignStage({dir / "A", dir / "B"}, dir / "M", TrackAlignOptions());
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no overlap found between A and B"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir / "M"));
  const auto r =
      test::RunCli("align " + (dir / "A").string() + " " + (dir / "B").string() + " -o " + (dir / "M2").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no overlap found between A and B"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "M2"));
}

TEST(AlignTracks, MissingSparseModelIsAClearError) {
  test::TempDir dir("fmv3d-tracks-bad");
  fs::create_directories(dir / "A");
  try {
    LoadTrack(dir / "A");
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fmv3d sparse"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace fmv3d::align
