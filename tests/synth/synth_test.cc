// fmv3d synth: output layout and ground truth, determinism, video round trip, option errors, realism (SIFT).
#include "fmv3d/synth/synth.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <iterator>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/synth/flight.h"
#include "fmv3d/synth/scene.h"
#include "test_util.h"

namespace fmv3d::synth {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

SynthOptions Small(const fs::path& out) {
  SynthOptions o;
  o.scene = SceneKind::kBuilding;
  o.flight.frames = 4;
  o.width = 320;
  o.height = 180;
  o.detail = 0.2;
  o.truth_points = 500;
  o.output = out;
  return o;
}

TEST(Synth, WritesFramesAndExactGroundTruth) {
  TempDir dir;
  SynthOptions o = Small(dir.path());
  o.distortion = {-0.05, 0.01, 0.0005, -0.0003};
  o.write_depth = true;
  const SynthResult r = RunSynth(o);
  EXPECT_EQ(r.frames, 4);
  EXPECT_DOUBLE_EQ(r.characteristic_length, 30.0);
  for (int k = 0; k < 4; ++k) {
    const cv::Mat img = cv::imread((dir / "frames" / FrameName(k)).string());
    ASSERT_FALSE(img.empty()) << FrameName(k);
    EXPECT_EQ(img.cols, 320);
    EXPECT_EQ(img.rows, 180);
    EXPECT_TRUE(fs::exists(dir / "depth" / ("flight-00000" + std::to_string(k) + ".tiff")));
  }
  EXPECT_EQ(FrameName(12), "flight-000012.png");
  EXPECT_TRUE(fs::exists(dir / "scene.obj"));
  EXPECT_TRUE(fs::exists(dir / "scene.mtl"));
  EXPECT_TRUE(fs::exists(dir / "ground.png"));
  const auto j = core::ReadJson(dir / "truth.json");
  EXPECT_DOUBLE_EQ(j["characteristic_length"].get<double>(), 30.0);
  EXPECT_EQ(j["seed"].get<uint64_t>(), 1u);
  EXPECT_DOUBLE_EQ(j["fps"].get<double>(), 10.0);
  EXPECT_DOUBLE_EQ(j["bounds"]["max"][2].get<double>(), 30.0);

  const core::Reconstruction truth = io::ReadColmapText(dir / "truth");
  ASSERT_EQ(truth.cameras.size(), 1u);
  const core::Camera& cam = truth.cameras.begin()->second;
  EXPECT_DOUBLE_EQ(cam.k1, -0.05);
  EXPECT_DOUBLE_EQ(cam.p2, -0.0003);
  EXPECT_NEAR(cam.fx(), 0.5 * 320 / std::tan(M_PI / 6), 1e-9);  // 60° horizontal field of view
  ASSERT_EQ(truth.images.size(), 4u);
  EXPECT_NE(truth.FindImageByName("flight-000003.png"), nullptr);
  // Truth points: the orbit sees the building from all sides; every observation is the exact projection
  // and the rendered depth there agrees with the point.
  EXPECT_GT(truth.points.size(), 100u);
  double worst = 0;
  for (const auto& [id, pt] : truth.points) {
    for (const auto& te : pt.track) {
      const core::Image& img = truth.images.at(te.image_id);
      const Eigen::Vector2d uv = cam.Project(img.pose.Transform(pt.xyz));
      worst = std::max(worst, (uv - img.points2d[te.point2d_idx]).norm());
    }
  }
  EXPECT_LT(worst, 1e-9);
  // The building is in the middle of every orbit frame: its centre projects near the image centre.
  for (const auto& [id, img] : truth.images) {
    const Eigen::Vector2d c = cam.Project(img.pose.Transform(Eigen::Vector3d(0, 0, 15)));
    EXPECT_LT((c - Eigen::Vector2d(160, 90)).norm(), 20) << img.name;
  }
}

TEST(Synth, SameSeedIsByteIdenticalDifferentSeedDiffers) {
  TempDir a, b, c;
  SynthOptions o = Small(a.path());
  o.flight.frames = 2;
  o.write_scene = false;
  RunSynth(o);
  o.output = b.path();
  RunSynth(o);
  o.output = c.path();
  o.flight.seed = 2;
  RunSynth(o);
  for (const char* f : {"frames/flight-000000.png", "frames/flight-000001.png", "truth/images.txt",
                        "truth/points3D.txt", "truth/cameras.txt"}) {
    EXPECT_EQ(Slurp(a / f), Slurp(b / f)) << f;
  }
  EXPECT_NE(Slurp(a / "frames/flight-000000.png"), Slurp(c / "frames/flight-000000.png"));
  EXPECT_NE(Slurp(a / "truth/images.txt"), Slurp(c / "truth/images.txt"));
}

TEST(Synth, VideoRoundTripKeepsSizeAndCountAndIsDeterministic) {
  for (const OutputFormat kind : {OutputFormat::kMp4, OutputFormat::kTs}) {
    const std::string format = OutputFormatName(kind);
    TempDir a, b;
    SynthOptions o = Small(a.path());
    o.flight.frames = 7;
    o.format = kind;
    o.write_scene = false;
    o.truth_points = 0;
    RunSynth(o);
    const fs::path video = a / ("flight." + format);
    ASSERT_TRUE(fs::exists(video)) << format;
    EXPECT_FALSE(fs::exists(a / "frames"));
    cv::VideoCapture cap(video.string());
    ASSERT_TRUE(cap.isOpened()) << format;
    int count = 0;
    cv::Mat frame, first;
    while (cap.read(frame)) {
      EXPECT_EQ(frame.cols, 320);
      EXPECT_EQ(frame.rows, 180);
      if (count == 0) first = frame.clone();
      ++count;
    }
    EXPECT_EQ(count, 7) << format;
    // The decoded first frame is close to the rendered one (lossy, but the same picture).
    const core::Reconstruction truth = io::ReadColmapText(a / "truth");
    EXPECT_EQ(truth.images.size(), 7u);
    EXPECT_EQ(truth.images.begin()->second.name, "flight-000000.png");
    o.output = b.path();
    RunSynth(o);
    EXPECT_EQ(Slurp(video), Slurp(b / ("flight." + format))) << format << " not byte-identical";
  }
}

TEST(Synth, VideoFrameMatchesRenderedFrame) {
  TempDir a, b;
  SynthOptions o = Small(a.path());
  o.flight.frames = 2;
  o.write_scene = false;
  o.truth_points = 0;
  RunSynth(o);
  o.output = b.path();
  o.format = OutputFormat::kMp4;
  RunSynth(o);
  cv::VideoCapture cap((b / "flight.mp4").string());
  cv::Mat decoded;
  ASSERT_TRUE(cap.read(decoded));
  const cv::Mat png = cv::imread((a / "frames/flight-000000.png").string());
  cv::Mat diff;
  cv::absdiff(decoded, png, diff);
  EXPECT_LT(cv::mean(diff)[1], 6.0);  // H.264 at crf 18 plus chroma subsampling
}

TEST(Synth, FlightsLookWhereTheyShould) {
  const Scene scene = MakeScene(SceneKind::kBoard);  // cheap scene; geometry only
  const core::Camera cam = core::Camera::Pinhole(640, 480, 554);
  FlightOptions o;
  o.frames = 12;
  o.jitter_deg = 0;
  o.position_jitter = 0;
  o.path = FlightPath::kGrid;
  for (const auto& p : MakeFlight(scene, cam, o)) EXPECT_NEAR(p.ViewDirection().z(), -1.0, 1e-12);
  o.path = FlightPath::kOrbit;
  const auto orbit = MakeFlight(scene, cam, o);
  ASSERT_EQ(orbit.size(), 12u);
  for (const auto& p : orbit) {
    const Eigen::Vector2d c = cam.Project(p.Transform(scene.target));
    EXPECT_LT((c - Eigen::Vector2d(320, 240)).norm(), 1e-6);
  }
  o.path = FlightPath::kPass;
  const auto pass = MakeFlight(scene, cam, o);
  EXPECT_GT((pass.back().Centre() - pass.front().Centre()).norm(), 0.5);
  // Jitter: bounded, seeded.
  o.path = FlightPath::kOrbit;
  o.jitter_deg = 0.5;
  const auto j1 = MakeFlight(scene, cam, o), j2 = MakeFlight(scene, cam, o);
  o.seed = 9;
  const auto j3 = MakeFlight(scene, cam, o);
  double max_angle = 0;
  for (size_t k = 0; k < j1.size(); ++k) {
    EXPECT_EQ(j1[k].q.coeffs(), j2[k].q.coeffs());
    max_angle = std::max(max_angle, core::RotationAngle(j1[k].q, orbit[k].q));
  }
  EXPECT_GT(max_angle, 0.05 * M_PI / 180);
  EXPECT_LT(max_angle, 3.0 * M_PI / 180);
  EXPECT_NE(j1[3].q.coeffs(), j3[3].q.coeffs());
}

// Height of the far-ground ring at (x, y): the triangle of material "far_ground" whose plan contains it (NaN: none).
double FarGroundHeight(const io::TexturedMesh& mesh, double x, double y) {
  for (const auto& f : mesh.faces) {
    if (f.material < 0 || mesh.materials[f.material].name != "far_ground") continue;
    const Eigen::Vector3d &a = mesh.vertices[f.v[0]], &b = mesh.vertices[f.v[1]], &c = mesh.vertices[f.v[2]];
    const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
    if (std::abs(det) < 1e-12) continue;
    const double u = ((x - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y - a.y())) / det;
    const double v = ((b.x() - a.x()) * (y - a.y()) - (x - a.x()) * (b.y() - a.y())) / det;
    if (u >= -1e-9 && v >= -1e-9 && u + v <= 1 + 1e-9) return a.z() + u * (b.z() - a.z()) + v * (c.z() - a.z());
  }
  return std::nan("");
}

// The far-ground ring meets the terrain tile without a step: just outside every side of the tile it stands where
// the tile's own edge does (a coarse ring cell alone stood metres off it: a cliff in every oblique view).
TEST(Synth, FarGroundMeetsTheTileWithoutAStep) {
  for (SceneKind kind : {SceneKind::kTerrain, SceneKind::kSand}) {
    SceneOptions o;
    o.detail = 0.1;  // small textures: the geometry is what is checked
    const Scene scene = MakeScene(kind, o);
    const Eigen::AlignedBox2d& t = scene.ground_extent;
    double worst = 0;
    int measured = 0;
    for (int k = 1; k < 100; ++k) {
      const double s = k / 100.0;
      const Eigen::Vector2d outside[4] = {{t.min().x() - 0.01, t.min().y() + s * t.sizes().y()},
                                          {t.max().x() + 0.01, t.min().y() + s * t.sizes().y()},
                                          {t.min().x() + s * t.sizes().x(), t.min().y() - 0.01},
                                          {t.min().x() + s * t.sizes().x(), t.max().y() + 0.01}};
      for (const auto& p : outside) {
        const double z = FarGroundHeight(scene.mesh, p.x(), p.y());
        ASSERT_TRUE(std::isfinite(z)) << SceneName(kind) << ": no far ground at " << p.transpose();
        worst = std::max(worst, std::abs(z - scene.ground_height(p.x(), p.y())));
        ++measured;
      }
    }
    std::printf("%s: far ground 1 cm outside the tile within %.3f m of the terrain (%d points)\n", SceneName(kind),
                worst, measured);
    EXPECT_LT(worst, 0.05) << SceneName(kind);  // the coarse ring alone: >= 0.3 m, up to metres
  }
}

TEST(Synth, BadOptionsAreErrors) {
  TempDir dir;
  SynthOptions o = Small(dir.path());
  o.width = 0;
  EXPECT_THROW(RunSynth(o), Error);
  o = Small(dir.path());
  o.flight.frames = 0;
  EXPECT_THROW(RunSynth(o), Error);
  try {
    ParseScene("moon");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("moon"), std::string::npos);
  }
  EXPECT_EQ(ParseScene("sand"), SceneKind::kSand);
  EXPECT_EQ(ParseFlightPath("oblique"), FlightPath::kOblique);
  EXPECT_EQ(ParseOutputFormat("ts"), OutputFormat::kTs);
  EXPECT_THROW(ParseFlightPath("spiral"), Error);
  EXPECT_THROW(ParseOutputFormat("gif"), Error);
  o = Small(dir.path());
  o.format = OutputFormat::kMp4;
  o.width = 343;
  o.height = 259;
  EXPECT_THROW(RunSynth(o), Error);
}

TEST(Synth, CliValidatesOptions) {
  TempDir dir;
  const std::string out = " -o " + dir.path().string();
  EXPECT_EQ(test::RunCli("synth --size 0x0" + out).exit_code, 2);
  EXPECT_EQ(test::RunCli("synth --size 640" + out).exit_code, 2);
  EXPECT_EQ(test::RunCli("synth --frames 0" + out).exit_code, 2);
  EXPECT_EQ(test::RunCli("synth --scene moon" + out).exit_code, 2);
  EXPECT_EQ(test::RunCli("synth --distortion 0.1,abc,0,0" + out).exit_code, 2);
  EXPECT_EQ(test::RunCli("synth --distortion 0.1,0.2" + out).exit_code, 2);
  const auto help = test::RunCli("synth --help");
  EXPECT_EQ(help.exit_code, 0);
  for (const char* opt : {"--scene", "--path", "--frames", "--size", "--focal", "--altitude", "--radius",
                          "--distortion", "--sun-azimuth", "--exposure", "--seed", "--format", "--fps"})
    EXPECT_NE(help.out.find(opt), std::string::npos) << opt;
  // Odd sizes work for image formats.
  const auto r = test::RunCli(
      "-q synth --scene terrain --path grid --frames 2 --size 343x259 --detail 0.1 "
      "--no-scene" +
      out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const cv::Mat img = cv::imread((dir / "frames/flight-000001.png").string());
  EXPECT_EQ(img.cols, 343);
  EXPECT_EQ(img.rows, 259);
}

TEST(Synth, ShippedBuildingObjIsTheProceduralBuilding) {
  const fs::path shipped = fs::path(__FILE__).parent_path().parent_path().parent_path() / "data/scenes/building.obj";
  const io::TexturedMesh built = MakeBuilding(BuildingSpec(), 0);
  if (std::getenv("FMV3D_UPDATE_SCENES")) io::WriteObj(built, shipped);
  ASSERT_TRUE(fs::exists(shipped)) << shipped;
  const io::TexturedMesh mesh = io::ReadObj(shipped);
  ASSERT_EQ(mesh.vertices.size(), built.vertices.size());
  ASSERT_EQ(mesh.faces.size(), built.faces.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) EXPECT_EQ(mesh.vertices[i], built.vertices[i]);
  const auto box = mesh.Bounds();
  EXPECT_DOUBLE_EQ(box.sizes().x(), 20.0);
  EXPECT_DOUBLE_EQ(box.sizes().y(), 12.0);
  EXPECT_DOUBLE_EQ(box.max().z(), 30.0);
  // Closed and outward: the divergence theorem gives the volume 20·12·24 + 20·(12·6/2).
  double volume = 0;
  for (const auto& f : mesh.faces)
    volume += mesh.vertices[f.v[0]].dot(mesh.vertices[f.v[1]].cross(mesh.vertices[f.v[2]])) / 6;
  EXPECT_NEAR(volume, 20 * 12 * 24 + 20 * 12 * 6 / 2.0, 1e-9);
}

TEST(Synth, ObjRoundTripKeepsGeometryUvsAndTextures) {
  TempDir dir;
  SceneOptions so;
  so.detail = 0.1;
  const Scene scene = MakeScene(SceneKind::kBuilding, so);
  io::WriteObj(scene.mesh, dir / "scene.obj");
  const io::TexturedMesh back = io::ReadObj(dir / "scene.obj");
  ASSERT_EQ(back.vertices.size(), scene.mesh.vertices.size());
  ASSERT_EQ(back.faces.size(), scene.mesh.faces.size());
  for (size_t i = 0; i < back.vertices.size(); ++i) ASSERT_EQ(back.vertices[i], scene.mesh.vertices[i]);
  for (size_t i = 0; i < back.uvs.size(); ++i) ASSERT_EQ(back.uvs[i], scene.mesh.uvs[i]);
  for (size_t i = 0; i < back.faces.size(); ++i) {
    ASSERT_EQ(back.faces[i].material, scene.mesh.faces[i].material);
    for (int k = 0; k < 3; ++k) ASSERT_EQ(back.faces[i].vt[k], scene.mesh.faces[i].vt[k]);
  }
  ASSERT_EQ(back.materials.size(), scene.mesh.materials.size());
  for (size_t m = 0; m < back.materials.size(); ++m) {
    const auto& a = back.materials[m].texture;
    const auto& b = scene.mesh.materials[m].texture;
    ASSERT_EQ(a.empty(), b.empty());
    if (!a.empty()) {
      EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0) << back.materials[m].name;
    }
  }
  EXPECT_THROW(io::ReadObj(dir / "missing.obj"), Error);
}

// Realism: SIFT (OpenCV, contrast threshold 0.02) must find thousands of keypoints spread over a
// 1280x720 town frame, as on real aerial imagery.
TEST(Synth, TownFramesAreRichInSiftFeatures) {
  SceneOptions so;
  so.detail = 0.5;  // half the texture resolution keeps the test fast; full detail gives ~2x more keypoints
  const Scene scene = MakeScene(SceneKind::kTown, so);
  SynthOptions o;
  o.scene = SceneKind::kTown;
  o.flight.frames = 8;
  const core::Camera cam = SynthCamera(o);
  const auto poses = MakeFlight(scene, cam, o.flight);
  const render::Renderer renderer(scene.mesh);
  const auto r = renderer.Render(cam, poses[3], o.render);
  cv::Mat gray;
  cv::cvtColor(r.image, gray, cv::COLOR_BGR2GRAY);
  auto sift = cv::SIFT::create(0, 3, 0.02);
  std::vector<cv::KeyPoint> kps;
  sift->detect(gray, kps);
  // Spread: keypoints in most cells of a 4x4 grid.
  int cells[16] = {0};
  for (const auto& k : kps) cells[std::min(3, int(k.pt.y / 180)) * 4 + std::min(3, int(k.pt.x / 320))]++;
  int filled = 0;
  for (int c : cells) filled += c >= 40;
  std::printf("SIFT keypoints on a 1280x720 town frame: %zu, 4x4 cells with >= 40: %d\n", kps.size(), filled);
  EXPECT_GT(kps.size(), 2000u);
  EXPECT_GE(filled, 14);
}

}  // namespace
}  // namespace fmv3d::synth

namespace fmv3d::synth {
namespace {

// The calibration board: OpenCV finds its 9x6 inner corners where the ground truth projects them.
TEST(Synth, ChessboardCornersLandWhereTheyProject) {
  const Scene scene = MakeScene(SceneKind::kBoard);
  SynthOptions o;
  o.scene = SceneKind::kBoard;
  o.width = 640;
  o.height = 480;
  o.distortion = {-0.1, 0.02, 0, 0};
  o.flight.frames = 6;
  const core::Camera cam = SynthCamera(o);
  const auto poses = MakeFlight(scene, cam, o.flight);
  const render::Renderer renderer(scene.mesh);
  double worst = 0;
  for (int k : {0, 2, 4}) {
    const auto r = renderer.Render(cam, poses[k], o.render);
    cv::Mat gray;
    cv::cvtColor(r.image, gray, cv::COLOR_BGR2GRAY);
    std::vector<cv::Point2f> corners;
    ASSERT_TRUE(cv::findChessboardCorners(gray, cv::Size(9, 6), corners)) << "frame " << k;
    cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
    // Match each detected corner to the nearest projected board corner (OpenCV's order may be reversed).
    for (const auto& c : corners) {
      double best = 1e9;
      for (int j = 0; j < 6; ++j)
        for (int i = 0; i < 9; ++i) {
          const Eigen::Vector2d p = cam.Project(poses[k].Transform(Eigen::Vector3d(i * 0.1, j * 0.1, 0)));
          best = std::min(best, (p - Eigen::Vector2d(c.x + 0.5, c.y + 0.5)).norm());
        }
      worst = std::max(worst, best);
    }
  }
  std::printf("chessboard corners vs projected truth: max %.3f px\n", worst);
  EXPECT_LT(worst, 0.25);
}

}  // namespace
}  // namespace fmv3d::synth
