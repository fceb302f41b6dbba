// Dense stereo on small synthetic flights rendered with exact cameras (`fmv3d synth`'s library entry): the
// true model is the sparse model, so depth maps and fused points are checked against the true depth and mesh.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/mvs/dense_stage.h"
#include "fmv3d/mvs/depth_map.h"
#include "fmv3d/mvs/evaluation.h"
#include "fmv3d/mvs/patch_match.h"
#include "fmv3d/mvs/view_selection.h"
#include "fmv3d/synth/synth.h"
#include "test_util.h"

namespace fmv3d::mvs {
namespace {

namespace fs = std::filesystem;

// Renders a small orbit around the single building once for all the test processes of the binary
// (test::SharedFixture); the workspace is frames/ + sparse/ (= the exact truth/ model with its sample tracks).
struct Flight {
  fs::path dir;
  synth::SynthResult result;  // the truth model and the characteristic length, as synth wrote them
};

const Flight& SmallFlight() {
  static const Flight flight = [] {
    Flight f;
    f.dir = test::SharedFixture("mvs-small-flight",
                                [](const fs::path& dir) {
                                  synth::SynthOptions so;
                                  so.scene = synth::SceneKind::kBuilding;
                                  so.width = 320;
                                  so.height = 240;
                                  so.flight.frames = 10;
                                  so.flight.jitter_deg = 0.2;
                                  so.detail = 0.5;
                                  so.truth_points = 1500;
                                  so.write_depth = true;
                                  so.output = dir / "synth";
                                  synth::RunSynth(so);
                                }) /
            "synth";
    f.result.truth = io::ReadColmapText(f.dir / "truth");
    f.result.characteristic_length = core::ReadJson(f.dir / "truth.json").at("characteristic_length").get<double>();
    f.result.frames = static_cast<int>(f.result.truth.images.size());
    return f;
  }();
  return flight;
}

fs::path MakeWorkspace(const test::TempDir& dir, const Flight& flight) {
  fs::path ws = dir / "ws";
  fs::create_directories(ws / "sparse");
  fs::copy(flight.dir / "frames", ws / "frames", fs::copy_options::recursive);
  io::WriteColmapText(flight.result.truth, ws / "sparse");
  return ws;
}

// Relative depth error of a photometric map of the first view against the rendered truth, over the pixels that
// at least two sources see. `relight` (if given) changes the source views' images before matching.
struct DepthCheck {
  int seen = 0, valid = 0, good = 0;     // good: within 1% of the true depth
  int seen2 = 0, valid2 = 0, good2 = 0;  // the same over the pixels that exactly two sources see
  double median = 1, p90 = 1;            // relative error of the valid pixels
};

// The small flight's first view and its (up to) 4 best sources by view selection, loaded; `relight` (if given)
// changes each source image after loading. Input() points into this object: keep it in place while it is used.
struct FirstViewSetup {
  View ref;
  std::vector<View> srcs;
  double depth_min = 0, depth_max = 0;
  size_t num_neighbours = 0;
  std::string problem;
  PatchMatchInput Input() const {
    PatchMatchInput in;
    in.ref = &ref;
    for (const auto& s : srcs) in.sources.push_back(&s);
    in.depth_min = depth_min;
    in.depth_max = depth_max;
    return in;
  }
};

FirstViewSetup LoadFirstView(const std::function<void(int, View*)>& relight = {}) {
  const Flight& flight = SmallFlight();
  const auto& rec = flight.result.truth;
  std::map<uint32_t, ViewGeometry> geoms;
  for (const auto& [id, im] : rec.images) geoms[id] = MakeViewGeometry(rec, id, 0);
  const auto sel = SelectViews(rec, geoms, {});
  const uint32_t ref_id = rec.images.begin()->first;
  const auto& rs = sel.at(ref_id);
  FirstViewSetup out;
  out.problem = rs.problem;
  out.num_neighbours = rs.neighbours.size();
  out.depth_min = rs.depth_min;
  out.depth_max = rs.depth_max;
  out.ref = LoadView(rec, geoms.at(ref_id), flight.dir / "frames");
  for (size_t k = 0; k < 4 && k < rs.neighbours.size(); ++k) {
    out.srcs.push_back(LoadView(rec, geoms.at(rs.neighbours[k].image_id), flight.dir / "frames"));
    if (relight) relight(static_cast<int>(k), &out.srcs.back());
  }
  return out;
}

template <typename Relight>
DepthCheck CheckFirstViewDepth(const Relight& relight, const PatchMatchOptions& opt = {}) {
  const Flight& flight = SmallFlight();
  const auto& rec = flight.result.truth;
  const uint32_t ref_id = rec.images.begin()->first;
  const FirstViewSetup setup = LoadFirstView(relight);
  EXPECT_TRUE(setup.problem.empty()) << setup.problem;
  EXPECT_GE(setup.num_neighbours, 3u);
  const View& ref = setup.ref;
  const auto& srcs = setup.srcs;
  const PatchMatchInput in = setup.Input();
  const DepthMap map = RunPatchMatch(in, opt);
  EXPECT_EQ(map.width(), 320);
  EXPECT_EQ(map.height(), 240);

  // Truth depth of the same (undistorted, full-size) pixels.
  const auto& name = rec.images.at(ref_id).name;
  const cv::Mat truth =
      cv::imread((flight.dir / "depth" / (fs::path(name).stem().string() + ".tiff")).string(), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(truth.type(), CV_32F);
  DepthCheck c;
  std::vector<float> rel;
  for (int y = 0; y < truth.rows; ++y)
    for (int x = 0; x < truth.cols; ++x) {
      const float t = truth.at<float>(y, x), d = map.depth.at<float>(y, x);
      if (!(t >= in.depth_min && t <= in.depth_max)) continue;  // sky, or the backdrop beyond the search range
      // Only surface that at least two sources see can be matched (the rest is left to the geometric pass
      // and fusion to remove).
      const Eigen::Vector3d X = ref.geom.Unproject({x + 0.5, y + 0.5}, t);
      int in_sources = 0;
      for (const auto& sv : srcs) {
        Eigen::Vector2d uv;
        in_sources += sv.geom.Project(X, &uv) && uv.x() > 5 && uv.y() > 5 && uv.x() < sv.geom.width - 5 &&
                      uv.y() < sv.geom.height - 5;
      }
      if (in_sources < 2) continue;
      ++c.seen;
      c.seen2 += in_sources == 2;
      if (!(d > 0)) continue;
      ++c.valid;
      c.good += std::abs(d - t) <= 0.01f * t;
      c.valid2 += in_sources == 2;
      c.good2 += in_sources == 2 && std::abs(d - t) <= 0.01f * t;
      rel.push_back(std::abs(d - t) / t);
    }
  std::sort(rel.begin(), rel.end());
  if (!rel.empty()) c.median = rel[rel.size() / 2], c.p90 = rel[rel.size() * 9 / 10];
  return c;
}

TEST(PatchMatch, DepthMatchesRenderedTruth) {
  const DepthCheck c = CheckFirstViewDepth([](int, View*) {});
  ASSERT_GT(c.seen, 1000);
  // Measured: valid 90.4% of the seen pixels, 57.4% of them within 1%, median 0.34%.
  EXPECT_GT(static_cast<double>(c.valid) / c.seen, 0.85) << c.valid << " of " << c.seen;
  // The photometric map alone keeps some wrong planes on weak texture (the geometric pass and fusion remove
  // them); most pixels must be right and the median well below 1%.
  EXPECT_LT(c.median, 0.0045);
  EXPECT_GT(static_cast<double>(c.good) / c.valid, 0.53)
      << c.good << " of " << c.valid << " within 1% of the true depth; relative error median " << c.median << ", p90 "
      << c.p90;
}

// PatchMatch averages the best top_k (3) source costs per pixel. A pixel that only two of the four sources see
// must still get its depth from those two: a source that cannot see the patch counts as uncorrelated, not as
// the worst match (which failed every such pixel: most of a photo survey's surface, seen by 2-3 views).
TEST(PatchMatch, PixelsThatOnlyTwoSourcesSeeGetTheirDepth) {
  const DepthCheck c = CheckFirstViewDepth([](int, View*) {});
  ASSERT_GT(c.seen2, 500);
  // Measured: 99.5% of 31,591 such pixels valid, 86.9% of them within 1% of the true depth; with the worst
  // cost for an unseeing source, 79% valid and 5.7% within 1%.
  EXPECT_GT(static_cast<double>(c.valid2) / c.seen2, 0.9) << c.valid2 << " of " << c.seen2;
  EXPECT_GT(static_cast<double>(c.good2) / c.valid2, 0.75) << c.good2 << " of " << c.valid2 << " within 1%";
}

// The 8-lane kernel scores planes as the 4-lane one does: the two maps are equally good.
TEST(PatchMatch, EightLaneKernelMatchesAsWellAsTheFourLane) {
  if (!Avx2KernelAvailable()) GTEST_SKIP() << "this CPU or build has no AVX2 kernel";
  PatchMatchOptions four, eight;
  four.use_avx2 = false;
  const DepthCheck a = CheckFirstViewDepth([](int, View*) {}, four);
  const DepthCheck b = CheckFirstViewDepth([](int, View*) {}, eight);
  ASSERT_GT(a.seen, 1000);
  ASSERT_EQ(a.seen, b.seen);
  std::printf("4 lanes: valid %d, within 1%% %d, median %.5f | 8 lanes: valid %d, within 1%% %d, median %.5f\n",
              a.valid, a.good, a.median, b.valid, b.good, b.median);
  EXPECT_NEAR(b.valid, a.valid, 0.01 * a.seen);
  EXPECT_NEAR(b.good, a.good, 0.01 * a.seen);
  EXPECT_NEAR(b.median, a.median, 0.05 * a.median);
}

// Sources exposed differently (gain 0.55–1.6, offsets, clipped and quantised like an 8-bit frame): the
// bilaterally weighted NCC is invariant to gain and bias, so the depth map must be as good as with equal light.
TEST(PatchMatch, SourcesWithOtherGainAndBiasMatchAsWell) {
  const DepthCheck same = CheckFirstViewDepth([](int, View*) {});
  const DepthCheck relit = CheckFirstViewDepth([](int k, View* v) {
    static const double kGain[4] = {0.55, 1.6, 0.8, 1.3}, kBias[4] = {0.2, -0.15, -0.05, 0.08};
    cv::Mat g = v->gray * kGain[k] + kBias[k];
    cv::Mat g8;
    g.convertTo(g8, CV_8U, 255);  // saturates like a real exposure
    g8.convertTo(v->gray, CV_32F, 1.0 / 255);
  });
  ASSERT_GT(relit.seen, 1000);
  std::printf("equal light: valid %d/%d, within 1%% %d, median %.5f | relit: valid %d/%d, within 1%% %d, median %.5f\n",
              same.valid, same.seen, same.good, same.median, relit.valid, relit.seen, relit.good, relit.median);
  const double valid_same = static_cast<double>(same.valid) / same.seen;
  const double valid_relit = static_cast<double>(relit.valid) / relit.seen;
  EXPECT_GT(valid_relit, valid_same - 0.05) << relit.valid << " of " << relit.seen;
  const double good_same = static_cast<double>(same.good) / same.valid;
  const double good_relit = static_cast<double>(relit.good) / relit.valid;
  EXPECT_GT(good_relit, good_same - 0.05);
  EXPECT_LT(relit.median, 1.25 * same.median + 1e-4)
      << "median relative depth error " << same.median << " → " << relit.median;
}

// Same seed, same maps — whatever the thread count (red–black updates, per-pixel random streams, and the
// change tracking / early termination of hypotheses must not depend on scheduling).
TEST(PatchMatch, DeterministicForAFixedSeedWhateverTheThreads) {
  const FirstViewSetup setup = LoadFirstView();
  const auto& srcs = setup.srcs;
  const PatchMatchInput in = setup.Input();
  PatchMatchOptions opt;
  opt.seed = 7;
  auto run = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return RunPatchMatch(in, opt);
  };
  const DepthMap a = run(1), b = run(2);
  // Geometric pass too (the photometric map of the reference stands in for its sources').
  PatchMatchInput gin = in;
  gin.init = &a;
  for (size_t k = 0; k < srcs.size(); ++k) gin.source_maps.push_back(&a);
  auto run_geom = [&](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    return RunPatchMatch(gin, opt);
  };
  const DepthMap ga = run_geom(1), gb = run_geom(3);
  for (const auto& [x, y] : {std::pair{&a, &b}, std::pair{&ga, &gb}}) {
    ASSERT_EQ(x->width(), y->width());
    EXPECT_EQ(cv::norm(x->depth, y->depth, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(x->normal, y->normal, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(x->cost, y->cost, cv::NORM_INF), 0.0);
  }
  EXPECT_GT(a.CountValid(), a.width() * a.height() / 2);
}

TEST(DenseStage, FusedPointsLieOnTheTrueSurface) {
  const Flight& flight = SmallFlight();
  test::TempDir dir("mvs_stage");
  const fs::path ws = MakeWorkspace(dir, flight);
  DenseStageOptions opt;
  opt.max_size = 0;
  opt.patch_match.iterations = 4;
  opt.patch_match.geom_iterations = 1;
  const auto report = RunDenseStage(ws, opt);
  EXPECT_EQ(report.at("views_used").get<int>(), 10);
  ASSERT_TRUE(fs::exists(ws / "dense" / "fused.ply"));
  ASSERT_TRUE(fs::exists(ws / "report" / "dense.json"));
  const std::string first = MapFileStem(flight.result.truth.images.begin()->second.name);
  EXPECT_TRUE(fs::exists(ws / "dense" / "maps" / (first + ".dmap")));
  EXPECT_TRUE(fs::exists(ws / "dense" / "maps" / (first + ".depth.png")));
  EXPECT_FALSE(fs::exists(ws / "dense" / "maps" / (first + ".photometric.dmap")));

  const io::OrientedPointCloud cloud = io::ReadPointCloudPly(ws / "dense" / "fused.ply");
  ASSERT_GT(cloud.size(), 20000u);
  EXPECT_EQ(cloud.size(), report.at("points").get<size_t>());
  ASSERT_TRUE(cloud.has_normals());
  ASSERT_TRUE(cloud.has_colors());
  ASSERT_TRUE(cloud.has_visibility());
  const auto& images = flight.result.truth.images;
  for (size_t i = 0; i < cloud.size(); i += 97) {
    ASSERT_GE(cloud.visibility[i].size(), static_cast<size_t>(opt.fusion.min_views));
    for (uint32_t id : cloud.visibility[i]) ASSERT_TRUE(images.count(id)) << id;
    EXPECT_NEAR(cloud.normals[i].norm(), 1.0, 1e-3);
    // The normal faces the cameras that see the point.
    const Eigen::Vector3d to_cam = images.at(cloud.visibility[i][0]).pose.Centre() - cloud.positions[i];
    EXPECT_GT(cloud.normals[i].cast<double>().dot(to_cam), 0);
  }

  const io::TexturedMesh scene = io::ReadObj(flight.dir / "scene.obj", false);
  const auto truth_json = core::ReadJson(flight.dir / "truth.json");
  DenseEvaluationOptions eo;
  eo.region = Eigen::AlignedBox3d(
      Eigen::Vector3d(truth_json["bounds"]["min"][0], truth_json["bounds"]["min"][1], truth_json["bounds"]["min"][2]),
      Eigen::Vector3d(truth_json["bounds"]["max"][0], truth_json["bounds"]["max"][1], truth_json["bounds"]["max"][2]));
  eo.keep_missed = true;
  const auto ev =
      EvaluateDense(cloud, flight.result.truth, flight.result.truth, scene, flight.result.characteristic_length, eo);
  // The missed samples are the seen ones without a point near: inside the region, and no point within the radius.
  ASSERT_EQ(ev.missed_samples.size(), ev.seen_samples - ev.complete_samples);
  const double radius = eo.completeness_fraction * flight.result.characteristic_length;
  for (size_t k = 0; k < ev.missed_samples.size(); k += std::max<size_t>(1, ev.missed_samples.size() / 20)) {
    EXPECT_TRUE(eo.region.contains(ev.missed_samples[k]));
    for (size_t i = 0; i < cloud.size(); i += 7) ASSERT_GT((cloud.positions[i] - ev.missed_samples[k]).norm(), radius);
  }
  // Accuracy in the region: the points of the two "inside" parts of the breakdown.
  EXPECT_EQ(ev.region_points, ev.breakdown[0].points + ev.breakdown[1].points);
  EXPECT_GT(ev.region_points, 0u);
  EXPECT_GT(ev.region_rms_error, 0);
  EXPECT_GE(ev.region_p90_error, ev.region_median_error);
  EXPECT_GT(report.at("fusion").at("texture_floor").get<double>(), 0);
  std::printf("fused: %zu points, median %.5f, p90 %.5f of the height, completeness %.4f\n", cloud.size(),
              ev.median_fraction(), ev.p90_fraction(), ev.completeness);
  // At 320x240 a pixel covers ~0.2 m of the 30 m building: points within a fraction of a pixel.
  EXPECT_LT(ev.median_fraction(), 0.004) << ev.ToJson().dump();
  EXPECT_LT(ev.p90_fraction(), 0.015) << ev.ToJson().dump();
  // At 320x240 most of the ground is seen with pixels wider than the 0.3 m completeness radius, so only
  // part of it can be complete (the 1280x720 figures are in the report).
  EXPECT_GT(ev.completeness, 0.12) << ev.ToJson().dump();

  // Re-fusing the same maps with a stricter view count: no PatchMatch, fewer points, each seen by >= 5 views.
  DenseStageOptions refuse = opt;
  refuse.fuse_only = true;
  refuse.fusion.min_views = 5;
  const auto report2 = RunDenseStage(ws, refuse);
  const io::OrientedPointCloud strict = io::ReadPointCloudPly(ws / "dense" / "fused.ply");
  EXPECT_EQ(strict.size(), report2.at("points").get<size_t>());
  EXPECT_LT(strict.size(), cloud.size());
  EXPECT_GT(strict.size(), cloud.size() / 4);
  for (size_t i = 0; i < strict.size(); i += 97) ASSERT_GE(strict.visibility[i].size(), 5u);
  // Without maps, --fuse-only says what to run.
  fs::remove_all(ws / "dense" / "maps");
  try {
    RunDenseStage(ws, refuse);
    FAIL() << "fuse-only without maps accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("without --fuse-only"), std::string::npos) << e.what();
  }
}

// With a reference cover only some views get a depth map; the others still serve as sources, and the fused
// points are as accurate as with every view. (10 frames 36° apart see each point a few times only: a cover
// of 2 leaves one view out; video keyframes, 20-30 views per point, leave out 1/2-2/3.)
TEST(DenseStage, ReferenceCoverMapsASubsetOfTheViews) {
  const Flight& flight = SmallFlight();
  test::TempDir dir("mvs_cover");
  const fs::path ws = MakeWorkspace(dir, flight);
  DenseStageOptions opt;
  opt.max_size = 0;
  opt.patch_match.iterations = 3;
  opt.geometric = false;
  opt.previews = false;
  opt.references.coverage = 2;
  const auto report = RunDenseStage(ws, opt);
  EXPECT_EQ(report.at("views_used").get<int>(), 10);
  const int refs = report.at("reference_views").get<int>();
  EXPECT_GE(refs, 3);
  EXPECT_LT(refs, 10);
  int maps = 0;
  for (const auto& e : fs::directory_iterator(ws / "dense" / "maps")) maps += e.path().extension() == ".dmap";
  EXPECT_EQ(maps, refs);
  const io::OrientedPointCloud cloud = io::ReadPointCloudPly(ws / "dense" / "fused.ply");
  ASSERT_GT(cloud.size(), 5000u);
  const io::TexturedMesh scene = io::ReadObj(flight.dir / "scene.obj", false);
  const auto ev =
      EvaluateDense(cloud, flight.result.truth, flight.result.truth, scene, flight.result.characteristic_length, {});
  // Without a region every point is in it.
  EXPECT_EQ(ev.region_median_error, ev.median_error);
  EXPECT_EQ(ev.region_p90_error, ev.p90_error);
  EXPECT_NEAR(ev.region_rms_error, ev.rms_error, 1e-12 * ev.rms_error);
  std::printf("cover of 2: %d of 10 views mapped, %zu points, median %.5f, p90 %.5f of the height\n", refs,
              cloud.size(), ev.median_fraction(), ev.p90_fraction());
  EXPECT_LT(ev.median_fraction(), 0.004) << ev.ToJson().dump();
  EXPECT_LT(ev.p90_fraction(), 0.015) << ev.ToJson().dump();
}

TEST(DenseStage, ViewWithoutNeighboursIsSkipped) {
  const Flight& flight = SmallFlight();
  test::TempDir dir("mvs_skip");
  const fs::path ws = MakeWorkspace(dir, flight);
  // An extra image looking straight up: it shares no surface with the others.
  core::Reconstruction rec = flight.result.truth;
  core::Image sky = rec.images.begin()->second;
  sky.id = 1000;
  sky.name = "sky.png";
  sky.points2d.clear();
  sky.point3d_ids.clear();
  sky.pose = core::Pose::LookAt(Eigen::Vector3d(0, 0, 200), Eigen::Vector3d(0, 0, 400), Eigen::Vector3d::UnitY());
  rec.images[sky.id] = sky;
  io::WriteColmapText(rec, ws / "sparse");
  fs::copy_file(ws / "frames" / rec.images.begin()->second.name, ws / "frames" / "sky.png");
  DenseStageOptions opt;
  opt.max_size = 160;
  opt.geometric = false;
  const auto report = RunDenseStage(ws, opt);
  EXPECT_EQ(report.at("views_used").get<int>(), 10);
  ASSERT_EQ(report.at("views_skipped").size(), 1u);
  EXPECT_EQ(report.at("views_skipped")[0].at("image").get<std::string>(), "sky.png");
}

TEST(DenseStage, BadInputGivesClearErrors) {
  const Flight& flight = SmallFlight();
  test::TempDir dir("mvs_bad");
  const fs::path ws = dir / "ws";
  fs::create_directories(ws);
  try {
    RunDenseStage(ws, {});
    FAIL() << "no sparse model accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fmv3d sparse"), std::string::npos) << e.what();
  }
  core::Reconstruction one = flight.result.truth;
  while (one.images.size() > 1) one.images.erase(std::prev(one.images.end()));
  one.points.clear();
  for (auto& [id, im] : one.images) std::fill(im.point3d_ids.begin(), im.point3d_ids.end(), core::kNoPoint3D);
  io::WriteColmapText(one, ws / "sparse");
  try {
    RunDenseStage(ws, {});
    FAIL() << "single-view model accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("at least 2"), std::string::npos) << e.what();
  }
  // Two registered images but their frames are missing.
  core::Reconstruction two = flight.result.truth;
  while (two.images.size() > 2) two.images.erase(std::prev(two.images.end()));
  two.points.clear();
  for (auto& [id, im] : two.images) std::fill(im.point3d_ids.begin(), im.point3d_ids.end(), core::kNoPoint3D);
  io::WriteColmapText(two, ws / "sparse");
  try {
    RunDenseStage(ws, {});
    FAIL() << "missing frames accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not found"), std::string::npos) << e.what();
  }
  DenseStageOptions bad;
  bad.max_sources = 0;
  EXPECT_THROW(bad.Check(), Error);
  bad = {};
  bad.patch_match.window_step = 0;
  EXPECT_THROW(bad.Check(), Error);
}

TEST(DepthMapFile, RoundTripAndCorruption) {
  test::TempDir dir("mvs_dmap");
  DepthMap m;
  m.depth = cv::Mat(7, 5, CV_32F);
  m.normal = cv::Mat(7, 5, CV_32FC3);
  m.cost = cv::Mat(7, 5, CV_32F);
  cv::randu(m.depth, 0, 10);
  cv::randu(m.normal, -1, 1);
  cv::randu(m.cost, 0, 2);
  WriteDepthMap(m, dir / "a.dmap");
  const DepthMap r = ReadDepthMap(dir / "a.dmap");
  ASSERT_EQ(r.width(), 5);
  ASSERT_EQ(r.height(), 7);
  EXPECT_EQ(cv::norm(m.depth, r.depth, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(m.normal, r.normal, cv::NORM_INF), 0);
  EXPECT_EQ(cv::norm(m.cost, r.cost, cv::NORM_INF), 0);
  // Truncated file.
  fs::resize_file(dir / "a.dmap", fs::file_size(dir / "a.dmap") - 4);
  EXPECT_THROW(ReadDepthMap(dir / "a.dmap"), Error);
  // Not a depth map.
  core::WriteTextFile(dir / "b.dmap", "hello, this is not a depth map at all");
  try {
    ReadDepthMap(dir / "b.dmap");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not an fmv3d depth map"), std::string::npos);
  }
}

}  // namespace
}  // namespace fmv3d::mvs
