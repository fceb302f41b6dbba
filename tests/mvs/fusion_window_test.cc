// Fusion through a bounded window of views (fusion_window.h): the window's size follows the memory budget,
// and a window smaller than the flight reloads views yet fuses exactly the points of an all-at-once fusion.
#include "fmv3d/mvs/fusion_window.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/io/point_cloud.h"
#include "test_util.h"

namespace fmv3d::mvs {
namespace {

TEST(FusionWindowSize, FollowsTheBudgetWithinItsBounds) {
  const double view = 10 * 1048576.0;                      // 10 MB per view
  EXPECT_EQ(ChooseFusionWindow(1000, 5, view, 100), 10u);  // what fits
  EXPECT_EQ(ChooseFusionWindow(1000, 5, view, 105), 10u);  // whole views only
  EXPECT_EQ(ChooseFusionWindow(1000, 5, view, 20), 5u);    // never below a reference with its neighbours
  EXPECT_EQ(ChooseFusionWindow(8, 5, view, 1e6), 8u);      // never more than there are
  EXPECT_EQ(ChooseFusionWindow(3, 5, view, 1), 3u);
  EXPECT_THROW(ChooseFusionWindow(10, 1, view, 0), Error);
  EXPECT_THROW(ChooseFusionWindow(10, 1, 0, 100), Error);
}

constexpr int kStripPx = 96;
constexpr double kStripCameraZ = 30.0, kStripBoxHalf = 1.0, kStripBoxZ = 4.0;

// Nadir cameras along a strip (1 m apart, a pixel ~0.25 m on the ground) over the ground with a box on it, each
// map with depth noise and a texture map that varies over the ground: occluding edges to erode, a texture floor
// to survey and points seen from up to five views.
FusionView StripView(uint32_t id, const std::vector<uint32_t>& neighbours) {
  ViewGeometry g;
  g.image_id = id;
  g.name = "s" + std::to_string(id);
  g.width = g.height = kStripPx;
  g.K << 120, 0, kStripPx / 2.0, 0, 120, kStripPx / 2.0, 0, 0, 1;
  g.R = Eigen::Vector3d(1, -1, -1).asDiagonal();
  g.t = -g.R * Eigen::Vector3d(1.0 * id, 0, kStripCameraZ);
  std::mt19937 rng(id);
  std::normal_distribution<double> gauss(0, 1);
  DepthMap map;
  map.depth.create(kStripPx, kStripPx, CV_32F);
  map.normal.create(kStripPx, kStripPx, CV_32FC3);
  map.cost = cv::Mat::zeros(kStripPx, kStripPx, CV_32F);
  cv::Mat texture(kStripPx, kStripPx, CV_32F), color(kStripPx, kStripPx, CV_8UC3);
  const Eigen::Vector3d c = g.Centre(), n = g.R * Eigen::Vector3d::UnitZ();
  for (int y = 0; y < kStripPx; ++y)
    for (int x = 0; x < kStripPx; ++x) {
      const Eigen::Vector3d ray = g.R.transpose() * g.K.inverse() * Eigen::Vector3d(x + 0.5, y + 0.5, 1);
      Eigen::Vector3d X = c + ray * (kStripBoxZ - c.z()) / ray.z();
      if (std::abs(X.x() - 5) > kStripBoxHalf || std::abs(X.y()) > kStripBoxHalf) X = c + ray * (-c.z() / ray.z());
      const double z = (g.R * X + g.t).z();
      map.depth.at<float>(y, x) = static_cast<float>(z + 2e-5 * z * z * gauss(rng));
      map.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
      texture.at<float>(y, x) = static_cast<float>(1 + 0.5 * std::sin(X.x()) + 0.1 * X.y());
      color.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(40 * id), static_cast<uchar>(x), static_cast<uchar>(y));
    }
  FusionView v = MakeFusionView(g, map, color, neighbours);
  texture.convertTo(v.texture, CV_16F);
  return v;
}

// Ten views, each linked to the next and previous and to the one five places away (a strip flown back): a
// view's map and used mask are needed again long after it left a small window.
std::map<uint32_t, FusionView> Strip() {
  std::map<uint32_t, FusionView> views;
  for (uint32_t id = 1; id <= 10; ++id) {
    std::vector<uint32_t> nbs;
    for (uint32_t j = 1; j <= 10; ++j)
      if (j != id && ((j + 1 >= id && j <= id + 1) || j + 5 == id || j == id + 5)) nbs.push_back(j);
    views.emplace(id, StripView(id, nbs));
  }
  return views;
}

TEST(FusionWindow, ASmallWindowFusesTheSamePointsAsAllViewsAtOnce) {
  const std::map<uint32_t, FusionView> views = Strip();
  FusionStats mem_st, win_st;
  const io::OrientedPointCloud mem = FuseDepthMaps(views, FusionOptions{}, &mem_st);

  std::vector<uint32_t> ids;
  ids.reserve(views.size());
  for (const auto& [id, v] : views) ids.push_back(id);
  size_t load_calls = 0;
  FusionWindow window(
      ids,
      [&](uint32_t id) {
        ++load_calls;
        FusionView v = views.at(id);
        v.depth = v.depth.clone();  // eroded in place by the window
        return v;
      },
      4, FusionOptions{});  // a reference and its (at most) three neighbours
  test::TempDir dir("fusion_window");
  const auto path = dir.path() / "fused.ply";
  const size_t n = FuseDepthMapsToPly(window, FusionOptions{}, path, &win_st);

  EXPECT_GT(window.loads(), ids.size());  // views were dropped and read again
  EXPECT_EQ(window.loads(), load_calls);
  EXPECT_LE(window.peak_resident(), 4u);
  const io::OrientedPointCloud ply = io::ReadPointCloudPly(path);
  ASSERT_GT(mem.size(), 1000u);
  ASSERT_EQ(n, mem.size());
  ASSERT_EQ(ply.size(), mem.size());
  EXPECT_GT(mem_st.edge_pixels, 0u);
  EXPECT_EQ(win_st.edge_pixels, mem_st.edge_pixels);  // each map eroded and counted once
  EXPECT_GT(mem_st.texture_floor, 0);
  EXPECT_EQ(win_st.texture_floor, mem_st.texture_floor);
  EXPECT_EQ(win_st.candidates, mem_st.candidates);  // the used masks survived eviction
  EXPECT_EQ(win_st.views_histogram, mem_st.views_histogram);
  for (size_t i = 0; i < mem.size(); ++i) {
    ASSERT_EQ(ply.positions[i], mem.positions[i].cast<float>().cast<double>()) << i;
    ASSERT_EQ(ply.colors[i], mem.colors[i]) << i;
    ASSERT_EQ(ply.visibility[i], mem.visibility[i]) << i;
    ASSERT_EQ(ply.sigma[i], mem.sigma[i]) << i;
  }
}

TEST(FusionWindow, RefusesUnknownViews) {
  FusionWindow window(
      {1, 2}, [](uint32_t id) { return StripView(id, {}); }, 1, FusionOptions{});
  EXPECT_THROW(window.Get(3), Error);
  EXPECT_THROW(FusionWindow(
                   {2, 1}, [](uint32_t id) { return StripView(id, {}); }, 1, FusionOptions{}),
               Error);
}

}  // namespace
}  // namespace fmv3d::mvs
