// Fusion of depth maps: the occluding-edge filter (fusion.h). PatchMatch "fattens" a foreground surface past
// its occluding edges (its window straddles the edge); neighbouring views fatten alike, so the extension is
// multi-view consistent and only removing the foreground side of depth discontinuities takes it away.
#include "fmv3d/mvs/fusion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <opencv2/imgproc.hpp>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/io/point_cloud.h"
#include "test_util.h"

namespace fmv3d::mvs {
namespace {

constexpr double kPlateHalf = 2.0, kPlateZ = 10.0, kCameraZ = 30.0;

// A nadir camera at (cx, cy, kCameraZ), 160x160 pixels, focal 200 (a pixel is 0.1 m on the plate).
ViewGeometry NadirView(uint32_t id, double cx, double cy) {
  ViewGeometry g;
  g.image_id = id;
  g.name = "v" + std::to_string(id);
  g.width = g.height = 160;
  g.K << 200, 0, 80, 0, 200, 80, 0, 0, 1;
  g.R = Eigen::Vector3d(1, -1, -1).asDiagonal();
  g.t = -g.R * Eigen::Vector3d(cx, cy, kCameraZ);
  return g;
}

// A view whose map holds, at each pixel, the world point `surface(centre, ray)` along the pixel's ray (normals up).
FusionView MakeViewOf(const ViewGeometry& g,
                      const std::function<Eigen::Vector3d(const Eigen::Vector3d&, const Eigen::Vector3d&)>& surface,
                      const std::vector<uint32_t>& neighbours) {
  DepthMap map;
  map.depth.create(g.height, g.width, CV_32F);
  map.normal.create(g.height, g.width, CV_32FC3);
  map.cost = cv::Mat::zeros(g.height, g.width, CV_32F);
  const Eigen::Vector3d c = g.Centre();
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      map.depth.at<float>(y, x) = static_cast<float>((g.R * surface(c, ray) + g.t).z());
      const Eigen::Vector3d n = g.R * Eigen::Vector3d::UnitZ();  // camera frame
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
    }
  return MakeFusionView(g, map, cv::Mat::zeros(g.height, g.width, CV_8UC3), neighbours);
}

// Depth map of a square plate (|x|, |y| <= kPlateHalf at z = kPlateZ) over the ground z = 0, with the plate
// continued `fatten` metres past its edges, as PatchMatch does at occluding edges.
FusionView MakeView(const ViewGeometry& g, double fatten, const std::vector<uint32_t>& neighbours) {
  return MakeViewOf(
      g,
      [fatten](const Eigen::Vector3d& c, const Eigen::Vector3d& ray) -> Eigen::Vector3d {
        const Eigen::Vector3d on_plate = c + ray * ((kPlateZ - c.z()) / ray.z());
        const bool plate =
            std::abs(on_plate.x()) <= kPlateHalf + fatten && std::abs(on_plate.y()) <= kPlateHalf + fatten;
        return plate ? on_plate : Eigen::Vector3d(c + ray * (-c.z() / ray.z()));
      },
      neighbours);
}

std::map<uint32_t, FusionView> FattenedPlate(double fatten) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 5; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 5; ++j)
      if (j != id) nbs.push_back(j);
    views.emplace(id, MakeView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), fatten, nbs));
  }
  return views;
}

struct Counts {
  size_t plate = 0, beyond_edge = 0, ground = 0;
};

Counts Classify(const io::OrientedPointCloud& cloud) {
  Counts c;
  for (const auto& p : cloud.positions) {
    const double r = std::max(std::abs(p.x()), std::abs(p.y()));
    if (p.z() > kPlateZ / 2) {
      if (r <= kPlateHalf + 0.05)
        ++c.plate;
      else
        ++c.beyond_edge;
    } else {
      ++c.ground;
    }
  }
  return c;
}

TEST(OccludingEdgeMask, MarksOnlyTheForegroundSideOfADepthStep) {
  cv::Mat depth(40, 40, CV_32F, cv::Scalar(20.0f));
  depth(cv::Rect(10, 10, 20, 20)).setTo(10.0f);  // foreground square
  depth(cv::Rect(0, 0, 5, 40)).setTo(0.0f);      // no depth at the left border: not an edge
  const cv::Mat mask = OccludingEdgeMask(depth, 3, 0.05);
  EXPECT_EQ(mask.at<uint8_t>(10, 10), 255);  // foreground corner
  EXPECT_EQ(mask.at<uint8_t>(20, 12), 255);  // 3 px inside the left edge
  EXPECT_EQ(mask.at<uint8_t>(20, 13), 0);    // 4 px inside: kept
  EXPECT_EQ(mask.at<uint8_t>(20, 20), 0);    // centre
  EXPECT_EQ(mask.at<uint8_t>(20, 9), 0);     // background next to the edge
  EXPECT_EQ(mask.at<uint8_t>(20, 5), 0);     // beside the pixels without depth
  EXPECT_EQ(mask.at<uint8_t>(20, 0), 0);     // no depth
  // A gentle slope (1% per pixel) is no edge.
  cv::Mat slope(20, 20, CV_32F);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 20; ++x) slope.at<float>(y, x) = 10.0f * (1 + 0.01f * x);
  EXPECT_EQ(cv::countNonZero(OccludingEdgeMask(slope, 3, 0.05)), 0);
}

// Ground z = 0 seen from 10 m up, looking 10° down with the horizon in the frame: near the horizon the depth
// grows by far more than 5% within a few pixels, yet every pixel lies on its neighbours' plane.
TEST(OccludingEdgeMask, GroundAtAGrazingAngleFollowsItsPlaneAndIsNoEdge) {
  ViewGeometry g;
  g.width = g.height = 160;
  g.K << 200, 0, 80, 0, 200, 80, 0, 0, 1;
  const double a = 10 * M_PI / 180;
  g.R.row(0) = Eigen::Vector3d(1, 0, 0);
  g.R.row(1) = Eigen::Vector3d(0, -std::sin(a), -std::cos(a));
  g.R.row(2) = Eigen::Vector3d(0, std::cos(a), -std::sin(a));
  g.t = -g.R * Eigen::Vector3d(0, 0, 10);
  DepthMap map;
  map.depth = cv::Mat::zeros(g.height, g.width, CV_32F);
  map.normal.create(g.height, g.width, CV_32FC3);
  map.cost = cv::Mat::zeros(g.height, g.width, CV_32F);
  const Eigen::Vector3d up = g.R * Eigen::Vector3d::UnitZ();
  int ground = 0;
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(up.x(), up.y(), up.z());
      if (ray.z() > -0.01) continue;  // sky, and ground beyond ~1 km
      map.depth.at<float>(y, x) = static_cast<float>(10 / -ray.z());
      ++ground;
    }
  const FusionView v = MakeFusionView(g, map, cv::Mat::zeros(g.height, g.width, CV_8UC3), {});
  ASSERT_GT(ground, 10000);
  EXPECT_GT(cv::countNonZero(OccludingEdgeMask(v.depth, 4, 0.05)), 1000);  // depth alone: a wide band
  EXPECT_EQ(cv::countNonZero(OccludingEdgeMask(v.depth, v.normal, v.geom, 4, 0.05)), 0);

  // A fattened plate's foreground side is an edge by either rule: the ground is far below the plate's plane.
  const auto plate = FattenedPlate(/*fatten=*/0.3);
  const FusionView& nadir = plate.at(1);
  const cv::Mat by_depth = OccludingEdgeMask(nadir.depth, 4, 0.05);
  const cv::Mat by_plane = OccludingEdgeMask(nadir.depth, nadir.normal, nadir.geom, 4, 0.05);
  EXPECT_GT(cv::countNonZero(by_depth), 100);
  EXPECT_EQ(cv::countNonZero(by_depth != by_plane), 0);
}

TEST(Fusion, EdgeErosionRemovesAFattenedOverhangAndKeepsThePlate) {
  const auto views = FattenedPlate(/*fatten=*/0.3);  // 3 pixels on the plate
  FusionOptions off;
  off.edge_erosion_px = 0;
  const Counts before = Classify(FuseDepthMaps(views, off));
  FusionOptions on;
  on.edge_erosion_px = 4;
  FusionStats st;
  const Counts after = Classify(FuseDepthMaps(views, on, &st));
  // Without the filter the consistent overhang is fused: a rim of points up to 0.3 m past the edge.
  EXPECT_GT(before.beyond_edge, 300u);
  EXPECT_EQ(after.beyond_edge, 0u);
  EXPECT_GT(st.edge_pixels, 0u);
  // The plate (40x40 pixels per view, less a 4-pixel rim) and the ground stay.
  EXPECT_GT(after.plate, 0.6 * before.plate);
  EXPECT_GT(after.ground, 0.95 * before.ground);
}

TEST(Fusion, EdgeOptionsAreChecked) {
  FusionOptions o;
  o.edge_erosion_px = -1;
  EXPECT_THROW(o.Check(), Error);
  o.edge_erosion_px = 2;
  o.edge_depth_jump = 0;
  EXPECT_THROW(o.Check(), Error);
}

// The uncertainty filter. Two nadir cameras 2b apart at height h over a point with an upward normal: each
// constrains the point perpendicular to its ray with one surface footprint r/f (r: range; the ray meets the
// surface at cos θ = h/r), so along the normal σ_n = r² / (√2 · b · f), the stereo depth uncertainty.
TEST(NormalUncertainty, MatchesTheTwoViewStereoFormula) {
  const double b = 1.5, f = 200;
  ViewGeometry left = NadirView(1, -b, 0), right = NadirView(2, b, 0);
  const Eigen::Vector3d X(0, 0, 0), n = Eigen::Vector3d::UnitZ();
  const double r = std::hypot(b, kCameraZ);
  EXPECT_NEAR(NormalUncertainty(X, n, {&left, &right}), r * r / (std::sqrt(2.0) * b * f), 1e-9);
  // Twice the baseline: half the uncertainty (almost: the range grows a little).
  ViewGeometry far_left = NadirView(3, -2 * b, 0), far_right = NadirView(4, 2 * b, 0);
  const double r2 = std::hypot(2 * b, kCameraZ);
  EXPECT_NEAR(NormalUncertainty(X, n, {&far_left, &far_right}), r2 * r2 / (std::sqrt(2.0) * 2 * b * f), 1e-9);
  // Matching twice as imprecise in both views (weaker texture): twice the uncertainty.
  EXPECT_NEAR(NormalUncertainty(X, n, {&left, &right}, {2.0, 2.0}), 2 * r * r / (std::sqrt(2.0) * b * f), 1e-9);
  // One view (or two on the same ray) leaves the point free along its ray.
  EXPECT_TRUE(std::isinf(NormalUncertainty(X, n, {&left})));
  EXPECT_TRUE(std::isinf(NormalUncertainty(X, n, {&left, &left})));
}

// Ground at z = 0 for x < kCliffX, a floor 90 m lower beyond: seen from 30 m, the floor is 4x farther, so its
// points are resolved 16x more coarsely along the normal (footprint x4, triangulation angle /4). Each view's
// depth has stereo-like noise growing with z² (the same disparity error everywhere), so the floor's points are
// 16x less accurate. Far surface resolved as well as its distance allows is kept, stating its larger σ.
constexpr double kCliffX = 6.0, kFloorZ = -90.0, kDisparityNoise = 1.2e-5;  // depth noise σ = k z²

FusionView CliffView(const ViewGeometry& g, const std::vector<uint32_t>& neighbours, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0, 1);
  DepthMap map;
  map.depth.create(g.height, g.width, CV_32F);
  map.normal.create(g.height, g.width, CV_32FC3);
  map.cost = cv::Mat::zeros(g.height, g.width, CV_32F);
  const Eigen::Vector3d c = g.Centre();
  const Eigen::Vector3d n = g.R * Eigen::Vector3d::UnitZ();
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      Eigen::Vector3d X = c + ray * (-c.z() / ray.z());
      if (X.x() >= kCliffX) X = c + ray * ((kFloorZ - c.z()) / ray.z());
      const double z = (g.R * X + g.t).z();
      map.depth.at<float>(y, x) = static_cast<float>(z + kDisparityNoise * z * z * gauss(rng));
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
    }
  return MakeFusionView(g, map, cv::Mat::zeros(g.height, g.width, CV_8UC3), neighbours);
}

struct CliffCounts {
  size_t ground = 0, floor = 0;
  double p90_error = 0;  // distance to the true plane, all points
};

CliffCounts ClassifyCliff(const io::OrientedPointCloud& cloud) {
  CliffCounts c;
  std::vector<double> err;
  for (const auto& p : cloud.positions) {
    const bool floor = p.z() < kFloorZ / 2;
    (floor ? c.floor : c.ground)++;
    err.push_back(std::abs(p.z() - (floor ? kFloorZ : 0.0)));
  }
  if (!err.empty()) {
    const size_t k = err.size() * 9 / 10;
    std::nth_element(err.begin(), err.begin() + static_cast<std::ptrdiff_t>(k), err.end());
    c.p90_error = err[k];
  }
  return c;
}

TEST(Fusion, UncertaintyFilterKeepsTheFarFloorAndStatesItsLargerSigma) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 5; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 5; ++j)
      if (j != id) nbs.push_back(j);
    views.emplace(id, CliffView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), nbs, id));
  }
  FusionOptions off;
  off.max_relative_uncertainty = 0;
  FusionStats st_off;
  const CliffCounts before = ClassifyCliff(FuseDepthMaps(views, off, &st_off));
  EXPECT_EQ(st_off.rejected_uncertainty, 0u);
  FusionOptions on;  // the default
  ASSERT_GT(on.max_relative_uncertainty, 0);
  FusionStats st;
  const io::OrientedPointCloud cloud = FuseDepthMaps(views, on, &st);
  const CliffCounts after = ClassifyCliff(cloud);
  std::printf("ground %zu -> %zu, floor %zu -> %zu, median sigma/footprint %.3f\n", before.ground, after.ground,
              before.floor, after.floor, st.median_uncertainty);
  ASSERT_GT(before.floor, before.ground / 5);
  // The floor is 4x farther but seen through the same baselines: as well resolved as its distance allows, kept.
  EXPECT_GT(after.floor, before.floor * 95 / 100);
  EXPECT_GT(after.ground, before.ground * 99 / 100);
  // Its stated σ is larger and still honest.
  ASSERT_TRUE(cloud.has_sigma());
  size_t n[2] = {0, 0}, over[2] = {0, 0};
  std::vector<double> sig[2];
  for (size_t i = 0; i < cloud.size(); ++i) {
    const bool floor = cloud.positions[i].z() < kFloorZ / 2;
    ++n[floor];
    over[floor] += std::abs(cloud.positions[i].z() - (floor ? kFloorZ : 0.0)) > cloud.sigma[i];
    sig[floor].push_back(cloud.sigma[i]);
  }
  for (int part = 0; part < 2; ++part) {
    ASSERT_GT(n[part], 100u);
    std::nth_element(sig[part].begin(), sig[part].begin() + sig[part].size() / 2, sig[part].end());
    std::printf("%s: %.2f%% over sigma, median sigma %.4f m\n", part ? "floor" : "ground", 100.0 * over[part] / n[part],
                sig[part][sig[part].size() / 2]);
    EXPECT_LE(static_cast<double>(over[part]) / n[part], 0.05) << part;
  }
  EXPECT_GT(sig[1][sig[1].size() / 2], 8 * sig[0][sig[0].size() / 2]);
  EXPECT_EQ(st.rejected_uncertainty, before.floor + before.ground - after.floor - after.ground);
  size_t hist = 0;
  for (const auto& [k, h] : st.views_histogram) hist += h;
  EXPECT_EQ(hist, after.floor + after.ground);
}

// Weak texture: the same flat ground everywhere, but for x > kWeakX the ground's texture is faint (the matching
// window locates 20x less precisely, so each view's depth there is 20x noisier). Only the texture maps tell
// the two halves apart; the filter must drop the faint half.
constexpr double kWeakX = 3.0, kWeakFactor = 20.0;

// texture_beyond / noise_beyond: the texture map's p and the depth noise (in units of the sharp half's) for
// x > kWeakX; both kWeakFactor by default (noise as the texture predicts).
FusionView TexturedGroundView(const ViewGeometry& g, const std::vector<uint32_t>& neighbours, uint32_t seed,
                              bool with_texture_map, double texture_beyond = kWeakFactor,
                              double noise_beyond = kWeakFactor) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0, 1);
  DepthMap map;
  map.depth.create(g.height, g.width, CV_32F);
  map.normal.create(g.height, g.width, CV_32FC3);
  map.cost = cv::Mat::zeros(g.height, g.width, CV_32F);
  cv::Mat texture(g.height, g.width, CV_32F);
  const Eigen::Vector3d c = g.Centre();
  const Eigen::Vector3d n = g.R * Eigen::Vector3d::UnitZ();
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      const Eigen::Vector3d X = c + ray * (-c.z() / ray.z());
      const bool beyond = X.x() > kWeakX;
      const double z = (g.R * X + g.t).z();
      map.depth.at<float>(y, x) =
          static_cast<float>(z + (beyond ? noise_beyond : 1.0) * kDisparityNoise * z * z * gauss(rng));
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
      texture.at<float>(y, x) = static_cast<float>(beyond ? texture_beyond : 1.0);
    }
  FusionView v = MakeFusionView(g, map, cv::Mat::zeros(g.height, g.width, CV_8UC3), neighbours);
  if (with_texture_map) texture.convertTo(v.texture, CV_16F);
  return v;
}

TEST(Fusion, UncertaintyFilterDropsWeaklyTexturedSurface) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  auto fuse = [&](bool with_texture_map, size_t* strong, size_t* weak, double* p90) {
    std::map<uint32_t, FusionView> views;
    for (uint32_t id = 1; id <= 5; ++id) {
      std::vector<uint32_t> nbs;
      for (uint32_t j = 1; j <= 5; ++j)
        if (j != id) nbs.push_back(j);
      views.emplace(
          id, TexturedGroundView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), nbs, id, with_texture_map));
    }
    const io::OrientedPointCloud cloud = FuseDepthMaps(views, FusionOptions{});
    *strong = *weak = 0;
    std::vector<double> err;
    for (const auto& p : cloud.positions) {
      if (p.x() > kWeakX + 0.5)
        ++*weak;
      else if (p.x() < kWeakX - 0.5)
        ++*strong;  // (a metre-wide band at the boundary is not counted)
      err.push_back(std::abs(p.z()));
    }
    const size_t k = err.size() * 9 / 10;
    std::nth_element(err.begin(), err.begin() + static_cast<std::ptrdiff_t>(k), err.end());
    *p90 = err[k];
  };
  size_t strong0, weak0, strong1, weak1;
  double p90_0, p90_1;
  fuse(false, &strong0, &weak0, &p90_0);  // geometry alone cannot tell the halves apart
  fuse(true, &strong1, &weak1, &p90_1);
  std::printf("no texture map: %zu + %zu faint, p90 %.4f m; with: %zu + %zu faint, p90 %.4f m\n", strong0, weak0, p90_0,
              strong1, weak1, p90_1);
  ASSERT_GT(weak0, strong0 / 4);
  EXPECT_LT(weak1, weak0 / 20);
  EXPECT_GT(strong1, strong0 * 98 / 100);
  EXPECT_LT(p90_1, p90_0 / 3);
}

// The pixel precision of a window is set by its gradients: a sharp checkerboard locates far better than the
// same board blurred and faded to a quarter of the contrast; a flat image is the worst (capped, finite), and a
// steep linear ramp is as bad: NCC, invariant to gain and bias, cannot tell a shifted ramp from the ramp.
TEST(TexturePrecisionMap, SharpTextureLocatesBetterThanFaintTexture) {
  cv::Mat board(64, 64, CV_8UC3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x)
      board.at<cv::Vec3b>(y, x) = ((x / 4 + y / 4) % 2) ? cv::Vec3b(200, 200, 200) : cv::Vec3b(40, 40, 40);
  cv::Mat faint;
  cv::GaussianBlur(board, faint, cv::Size(0, 0), 2.0);
  faint.convertTo(faint, -1, 0.25, 90);
  const cv::Mat flat(64, 64, CV_8UC3, cv::Scalar(100, 100, 100));
  auto centre = [](const cv::Mat& m) { return static_cast<double>(m.at<cv::float16_t>(32, 32)); };
  const double sharp = centre(TexturePrecisionMap(board, 5)), weak = centre(TexturePrecisionMap(faint, 5)),
               none = centre(TexturePrecisionMap(flat, 5));
  std::printf("pixel precision: sharp %.3f, faint %.3f, flat %.1f\n", sharp, weak, none);
  EXPECT_GT(weak, 6 * sharp);
  EXPECT_GT(none, 100 * weak);
  EXPECT_TRUE(std::isfinite(none));
  EXPECT_EQ(TexturePrecisionMap(board, 5).type(), CV_16F);
  cv::Mat ramp(64, 64, CV_8UC3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) ramp.at<cv::Vec3b>(y, x) = cv::Vec3b::all(static_cast<uchar>(30 + 3 * x));
  const double steep = centre(TexturePrecisionMap(ramp, 5));
  std::printf("ramp of 3 grey levels per pixel: %.1f\n", steep);
  EXPECT_GT(steep, 100 * weak);
}

// The streaming variant writes exactly the points the in-memory fusion returns (with the filter at work).
TEST(Fusion, StreamingToPlyMatchesTheInMemoryCloud) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 5; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 5; ++j)
      if (j != id) nbs.push_back(j);
    views.emplace(id, TexturedGroundView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), nbs, id, true));
  }
  FusionStats mem_st, ply_st;
  const io::OrientedPointCloud mem = FuseDepthMaps(views, FusionOptions{}, &mem_st);
  test::TempDir dir("fusion_ply");
  const auto path = dir.path() / "fused.ply";
  const size_t n = FuseDepthMapsToPly(views, FusionOptions{}, path, &ply_st);
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".unfiltered"));
  const io::OrientedPointCloud ply = io::ReadPointCloudPly(path);
  ASSERT_EQ(n, mem.size());
  ASSERT_EQ(ply.size(), mem.size());
  ASSERT_GT(mem_st.rejected_uncertainty, 0u);
  EXPECT_EQ(ply_st.rejected_uncertainty, mem_st.rejected_uncertainty);
  EXPECT_EQ(ply_st.edge_pixels, mem_st.edge_pixels);
  EXPECT_EQ(ply_st.views_histogram, mem_st.views_histogram);
  EXPECT_EQ(ply_st.median_uncertainty, mem_st.median_uncertainty);
  for (size_t i = 0; i < mem.size(); ++i) {
    ASSERT_EQ(ply.positions[i], mem.positions[i].cast<float>().cast<double>()) << i;
    ASSERT_EQ(ply.normals[i], mem.normals[i]) << i;
    ASSERT_EQ(ply.colors[i], mem.colors[i]) << i;
    ASSERT_EQ(ply.visibility[i], mem.visibility[i]) << i;
  }
  ASSERT_TRUE(mem.has_sigma());
  ASSERT_TRUE(ply.has_sigma());
  EXPECT_EQ(ply_st.sigma_scale, mem_st.sigma_scale);
  for (size_t i = 0; i < mem.size(); ++i) ASSERT_EQ(ply.sigma[i], mem.sigma[i]) << i;
}

// Per part of the weak-texture ground (0: x < kWeakX, 1: beyond; a 0.5 m band at the edge left out): points,
// the share whose true error (|z|) exceeds their stated σ, and the median σ.
struct SigmaTally {
  size_t n[2] = {0, 0};
  double over_fraction[2] = {0, 0}, median_sigma[2] = {0, 0};
};

SigmaTally TallySigma(const io::OrientedPointCloud& cloud) {
  SigmaTally t;
  size_t over[2] = {0, 0};
  std::vector<double> sig[2];
  for (size_t i = 0; i < cloud.size(); ++i) {
    const auto& p = cloud.positions[i];
    if (std::abs(p.x() - kWeakX) < 0.5) continue;
    const int part = p.x() > kWeakX ? 1 : 0;
    ++t.n[part];
    over[part] += std::abs(p.z()) > cloud.sigma[i];
    sig[part].push_back(cloud.sigma[i]);
  }
  for (int part = 0; part < 2; ++part) {
    if (sig[part].empty()) continue;
    std::nth_element(sig[part].begin(), sig[part].begin() + sig[part].size() / 2, sig[part].end());
    t.over_fraction[part] = static_cast<double>(over[part]) / t.n[part];
    t.median_sigma[part] = sig[part][sig[part].size() / 2];
  }
  return t;
}

// The stated σ of every fused point (world units, calibrated by the cloud's own spread) bounds its true error
// in all but a few cases, on sharp and on faint texture alike, and is larger where the texture is faint.
TEST(Fusion, StatedSigmaBoundsTheTrueErrorAndFollowsTheTexture) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 5; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 5; ++j)
      if (j != id) nbs.push_back(j);
    views.emplace(id, TexturedGroundView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), nbs, id, true));
  }
  FusionOptions opt;
  opt.max_relative_uncertainty = 0;  // keep the faint half, to check its σ too
  FusionStats st;
  const io::OrientedPointCloud cloud = FuseDepthMaps(views, opt, &st);
  ASSERT_TRUE(cloud.has_sigma());
  EXPECT_GT(st.sigma_scale, 0);
  const SigmaTally t = TallySigma(cloud);
  ASSERT_GT(t.n[0], 1000u);
  ASSERT_GT(t.n[1], 1000u);
  for (int part = 0; part < 2; ++part) {
    std::printf("%s: %zu points, %.2f%% over sigma, median sigma %.4f m\n", part ? "faint" : "sharp", t.n[part],
                100.0 * t.over_fraction[part], t.median_sigma[part]);
    EXPECT_LE(t.over_fraction[part], 0.05) << part;
  }
  EXPECT_GT(t.median_sigma[1], 5 * t.median_sigma[0]);
}

// Window matching does not get better without bound as the texture sharpens: past the clip's typical texture
// other errors (interpolation, the planar patch) dominate. Here the part beyond kWeakX has a texture map that
// promises 10x the precision of the rest, but its depths are as noisy: its stated σ must not promise 10x.
TEST(Fusion, StatedSigmaHasAMatchingFloorOnSharpTexture) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  auto fuse = [&](double floor_quantile, double over_fraction[2], double median_sigma[2]) {
    std::map<uint32_t, FusionView> views;
    for (uint32_t id = 1; id <= 5; ++id) {
      std::vector<uint32_t> nbs;
      for (uint32_t j = 1; j <= 5; ++j)
        if (j != id) nbs.push_back(j);
      views.emplace(id, TexturedGroundView(NadirView(id, offsets[id - 1][0], offsets[id - 1][1]), nbs, id, true,
                                           /*texture_beyond=*/0.1, /*noise_beyond=*/1.0));
    }
    FusionOptions opt;
    opt.texture_floor_quantile = floor_quantile;
    FusionStats st;
    const io::OrientedPointCloud cloud = FuseDepthMaps(views, opt, &st);
    ASSERT_TRUE(cloud.has_sigma());
    EXPECT_EQ(st.texture_floor > 0, floor_quantile > 0);
    const SigmaTally t = TallySigma(cloud);
    for (int part = 0; part < 2; ++part) {
      ASSERT_GT(t.n[part], 1000u);
      over_fraction[part] = t.over_fraction[part];
      median_sigma[part] = t.median_sigma[part];
    }
    std::printf("floor quantile %.2f: %.2f%% / %.2f%% over sigma (rest / sharp), median sigma %.4f / %.4f m\n",
                floor_quantile, 100 * over_fraction[0], 100 * over_fraction[1], median_sigma[0], median_sigma[1]);
  };
  double over[2], sigma[2];
  fuse(0, over, sigma);  // no floor: the sharp part's σ is ~10x too small
  EXPECT_GT(over[1], 0.3);
  fuse(FusionOptions{}.texture_floor_quantile, over, sigma);
  EXPECT_LE(over[0], 0.05);
  EXPECT_LE(over[1], 0.05);
  EXPECT_GT(sigma[1], 0.5 * sigma[0]);
}

TEST(Fusion, UncertaintyOptionIsChecked) {
  FusionOptions o;
  o.max_relative_uncertainty = 0.5;  // would drop half the cloud by definition
  EXPECT_THROW(o.Check(), Error);
  o.max_relative_uncertainty = -1;
  EXPECT_THROW(o.Check(), Error);
  o.max_relative_uncertainty = 0;
  EXPECT_NO_THROW(o.Check());
  o.texture_floor_quantile = 1;
  EXPECT_THROW(o.Check(), Error);
  o.texture_floor_quantile = -0.1;
  EXPECT_THROW(o.Check(), Error);
}

// Sparse-point contradiction (fusion.h): a map piece locked one period off on periodic texture is dropped by the
// sparse points the view observed there; a roof with its own points, far land with none and a piece only two
// points contradict are kept.
TEST(SparseContradictionMask, DropsThePieceItsSparsePointsContradict) {
  cv::Mat depth(60, 90, CV_32F, cv::Scalar(100.0f));
  for (int y = 0; y < 60; ++y)  // the ground slopes away gently (0.1% per row): one piece
    for (int x = 0; x < 90; ++x) depth.at<float>(y, x) = 100.0f * (1 + 0.001f * y);
  depth(cv::Rect(5, 5, 20, 20)).setTo(130.0f);    // aliased: 30% too deep
  depth(cv::Rect(40, 5, 20, 20)).setTo(70.0f);    // a roof
  depth(cv::Rect(65, 30, 20, 20)).setTo(400.0f);  // far land, no sparse point reaches it
  depth(cv::Rect(5, 35, 20, 20)).setTo(150.0f);   // only two points say otherwise
  depth(cv::Rect(0, 58, 90, 2)).setTo(0.0f);      // no depth
  std::vector<SparseDepth> uvz;
  const auto add = [&uvz](double u, double v, double z) { uvz.push_back({u, v, z, 0.05}); };
  for (int y = 2; y < 60; y += 4)
    for (int x = 2; x < 90; x += 4) {
      const bool roof = x >= 40 && x < 60 && y >= 5 && y < 25, far = x >= 65 && x < 85 && y >= 30 && y < 50;
      const bool weak = x >= 5 && x < 25 && y >= 35 && y < 55;
      if (far || weak) continue;
      add(x + 0.5, y + 0.5, roof ? 70.2 : 100.0 * (1 + 0.001 * y));  // the aliased patch's are ground
    }
  add(10.5, 40.5, 100.0);
  add(20.5, 50.5, 100.0);
  add(15.5, 45.5, 151.0);  // one agrees with the weakly contradicted piece
  add(-3, 10, 100.0);      // outside the map: ignored
  size_t pieces = 0;
  const cv::Mat mask = SparseContradictionMask(depth, uvz, 0.05, 3, &pieces);
  EXPECT_EQ(pieces, 1u);
  EXPECT_EQ(cv::countNonZero(mask), 400);
  EXPECT_EQ(mask.at<uint8_t>(15, 15), 255);
  EXPECT_EQ(mask.at<uint8_t>(15, 50), 0);
  EXPECT_EQ(mask.at<uint8_t>(40, 75), 0);
  EXPECT_EQ(mask.at<uint8_t>(45, 15), 0);
  EXPECT_EQ(mask.at<uint8_t>(30, 30), 0);
  // Without sparse points nothing is dropped.
  EXPECT_EQ(cv::countNonZero(SparseContradictionMask(depth, {}, 0.05, 3)), 0);
  // Points whose own depth is uncertain (triangulated from a short baseline) do not overrule the map: the
  // aliased patch's points with 0.2° of parallax agree within 3 / (f · sin α) (f 200: 4.3, i.e. 430%).
  for (auto& s : uvz)
    if (s.u >= 5 && s.u < 25 && s.v >= 5 && s.v < 25) s.tolerance = 4.3;
  EXPECT_EQ(cv::countNonZero(SparseContradictionMask(depth, uvz, 0.05, 3)), 0);
}

TEST(SparseContradictionMask, ToleranceGrowsAsTheTrackNarrows) {
  ViewGeometry g;
  g.width = g.height = 100;
  g.K << 500, 0, 50, 0, 500, 50, 0, 0, 1;
  const double pi = std::acos(-1.0);
  const auto d = SparseDepthsIn(g,
                                {{Eigen::Vector3d(0, 0, 10), 30 * pi / 180},
                                 {Eigen::Vector3d(1, 0, 100), 0.5 * pi / 180},
                                 {Eigen::Vector3d(0, 0, -5), 0.5}},
                                0.05);
  ASSERT_EQ(d.size(), 2u);                                                   // the point behind the camera is left out
  EXPECT_DOUBLE_EQ(d[0].tolerance, 0.05);                                    // 3 / (500 · 0.5) = 1.2%: the floor
  EXPECT_NEAR(d[1].tolerance, 3 / (500 * std::sin(0.5 * pi / 180)), 1e-12);  // 68.8%
  EXPECT_NEAR(d[1].u, 55, 1e-9);
  EXPECT_NEAR(d[1].depth, 100, 1e-9);
}

// Five nadir views whose maps all hold the same aliased patch 5 m under the ground: fused without the test it
// becomes a multi-view consistent underground surface; with the views' sparse points (on the true ground) it is
// gone and the ground around it is kept.
TEST(Fusion, SparsePointsDropAnAliasedPatchEveryViewAgreesOn) {
  const double offsets[5][2] = {{0, 0}, {1.5, 1.5}, {-1.5, 1.5}, {1.5, -1.5}, {-1.5, -1.5}};
  const auto aliased = [](const Eigen::Vector3d& g) { return std::abs(g.x()) <= 1.5 && std::abs(g.y()) <= 1.5; };
  std::vector<SparseObservation> ground_points;  // seen from across the five views: 17° of parallax
  for (double x = -3.9; x <= 3.9; x += 0.3)
    for (double y = -3.9; y <= 3.9; y += 0.3) ground_points.push_back({Eigen::Vector3d(x, y, 0), 0.3});
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 5; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 5; ++j)
      if (j != id) nbs.push_back(j);
    FusionView v = MakeViewOf(
        NadirView(id, offsets[id - 1][0], offsets[id - 1][1]),
        [&aliased](const Eigen::Vector3d& c, const Eigen::Vector3d& ray) -> Eigen::Vector3d {
          const double z = aliased(c + ray * (-c.z() / ray.z())) ? -5.0 : 0.0;
          return c + ray * ((z - c.z()) / ray.z());
        },
        nbs);
    v.sparse = ground_points;
    views.emplace(id, std::move(v));
  }
  FusionOptions opt;
  opt.write_sigma = false;
  opt.max_relative_uncertainty = 0;
  const auto count = [](const io::OrientedPointCloud& cloud, bool below) {
    return std::count_if(cloud.positions.begin(), cloud.positions.end(),
                         [below](const Eigen::Vector3d& p) { return below ? p.z() < -1 : std::abs(p.z()) < 0.1; });
  };
  opt.sparse_tolerance = 0;
  const auto plain = FuseDepthMaps(views, opt);
  EXPECT_GT(count(plain, true), 100);
  opt.sparse_tolerance = 0.05;
  FusionStats st;
  const auto checked = FuseDepthMaps(views, opt, &st);
  EXPECT_EQ(count(checked, true), 0);
  EXPECT_EQ(st.sparse_pieces, 5u);
  EXPECT_GT(count(checked, false), count(plain, false) * 9 / 10);
  opt.sparse_min_votes = 0;
  EXPECT_THROW(opt.Check(), Error);
}

}  // namespace
}  // namespace fmv3d::mvs
