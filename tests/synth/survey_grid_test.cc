// The survey test data: a nadir grid at stated forward / side overlaps, over the low-texture `sand` scene.
#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/synth/flight.h"
#include "fmv3d/synth/scene.h"

namespace fmv3d::synth {
namespace {

TEST(SurveyGrid, FramesAreLaidOutAtTheStatedOverlaps) {
  SceneOptions so;
  so.detail = 0.1;
  const Scene scene = MakeScene(SceneKind::kSand, so);
  core::Camera cam = core::Camera::Pinhole(1600, 900, 800 / std::tan(M_PI / 6));
  FlightOptions fo;
  fo.path = FlightPath::kGrid;
  fo.frames = 60;
  fo.altitude = 110;
  fo.grid_overlap = std::make_pair(0.7, 0.4);
  fo.jitter_deg = 0;
  fo.position_jitter = 0;
  const auto poses = MakeFlight(scene, cam, fo);
  ASSERT_EQ(poses.size(), 60u);
  const double h = 110 - scene.target.z();
  const double along = 0.3 * h * cam.height / cam.fy(), across = 0.6 * h * cam.width / cam.fx();
  // Consecutive frames of the first strip: `along` apart, same x; the next strip `across` east.
  EXPECT_NEAR((poses[1].Centre() - poses[0].Centre()).norm(), along, 1e-6);
  EXPECT_NEAR(poses[1].Centre().x(), poses[0].Centre().x(), 1e-9);
  double max_x = -1e9, min_x = 1e9;
  for (const auto& p : poses) max_x = std::max(max_x, p.Centre().x()), min_x = std::min(min_x, p.Centre().x());
  const double strips = std::round((max_x - min_x) / across) + 1;
  EXPECT_NEAR(std::fmod(max_x - min_x, across), 0, 1e-6);
  EXPECT_GE(strips, 3);
  // Nadir: optical axis straight down.
  EXPECT_NEAR((poses[7].q.conjugate() * Eigen::Vector3d::UnitZ()).z(), -1, 1e-9);
}

TEST(SurveyGrid, SandIsFaintBesideTheTerrainScene) {
  SceneOptions so;
  so.detail = 0.1;
  auto contrast = [&](SceneKind kind) {
    const Scene s = MakeScene(kind, so);
    // Local contrast: what is left after removing the structure broader than a few texels.
    cv::Mat tex, smooth;
    s.mesh.materials.front().texture.convertTo(tex, CV_32FC3);
    cv::GaussianBlur(tex, smooth, cv::Size(0, 0), 3);
    cv::Scalar mean, sd;
    cv::meanStdDev(tex - smooth, mean, sd);
    return (sd[0] + sd[1] + sd[2]) / 3;
  };
  const double sand = contrast(SceneKind::kSand), terrain = contrast(SceneKind::kTerrain);
  std::printf("local texture contrast (standard deviation): sand %.1f DN, terrain %.1f DN\n", sand, terrain);
  EXPECT_LT(sand, 0.5 * terrain);
}

TEST(SurveyGrid, OverlapOutOfRangeIsAnError) {
  FlightOptions fo;
  fo.path = FlightPath::kGrid;
  fo.grid_overlap = std::make_pair(1.2, 0.4);
  EXPECT_THROW(fo.Check(), Error);
}

}  // namespace
}  // namespace fmv3d::synth
