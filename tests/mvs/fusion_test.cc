// Fusion of depth maps: the occluding-edge filter (fusion.h). PatchMatch "fattens" a foreground surface past
// its occluding edges (its window straddles the edge); neighbouring views fatten alike, so the extension is
// multi-view consistent and only removing the foreground side of depth discontinuities takes it away.
#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/mvs/fusion.h"

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

// Depth map of a square plate (|x|, |y| <= kPlateHalf at z = kPlateZ) over the ground z = 0, with the plate
// continued `fatten` metres past its edges, as PatchMatch does at occluding edges.
FusionView MakeView(const ViewGeometry& g, double fatten, const std::vector<uint32_t>& neighbours) {
  DepthMap map;
  map.depth.create(g.height, g.width, CV_32F);
  map.normal.create(g.height, g.width, CV_32FC3);
  map.cost = cv::Mat::zeros(g.height, g.width, CV_32F);
  const Eigen::Vector3d c = g.Centre();
  for (int y = 0; y < g.height; ++y)
    for (int x = 0; x < g.width; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      const Eigen::Vector3d on_plate = c + ray * ((kPlateZ - c.z()) / ray.z());
      const bool plate = std::abs(on_plate.x()) <= kPlateHalf + fatten && std::abs(on_plate.y()) <= kPlateHalf + fatten;
      const Eigen::Vector3d X = plate ? on_plate : Eigen::Vector3d(c + ray * (-c.z() / ray.z()));
      map.depth.at<float>(y, x) = static_cast<float>((g.R * X + g.t).z());
      const Eigen::Vector3d n = g.R * Eigen::Vector3d::UnitZ();  // camera frame
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
    }
  return MakeFusionView(g, map, cv::Mat::zeros(g.height, g.width, CV_8UC3), neighbours);
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
      if (r <= kPlateHalf + 0.05) ++c.plate;
      else ++c.beyond_edge;
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

}  // namespace
}  // namespace fmv3d::mvs
