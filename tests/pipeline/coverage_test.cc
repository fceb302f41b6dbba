// Per-view coverage (pipeline/coverage.h): the sky found in a rendered frame, and the shares of the non-sky
// pixels that a mesh and a point cloud cover, against what the true geometry says.
#include "fmv3d/pipeline/coverage.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/render/renderer.h"

namespace fmv3d::pipeline {
namespace {

// A flat ground square z = 0 over [-side, side]² in y ≥ y_from, split into cells (two triangles each), in a
// brownish green that is nothing like sky.
io::TexturedMesh Ground(double side, double y_from, int cells) {
  io::TexturedMesh m;
  io::Material mat;
  mat.diffuse_bgr = {0.25f, 0.45f, 0.5f};
  m.materials.push_back(mat);
  const double y0 = std::max(-side, y_from);
  for (int j = 0; j <= cells; ++j)
    for (int i = 0; i <= cells; ++i)
      m.vertices.emplace_back(-side + 2 * side * i / cells, y0 + (side - y0) * j / cells, 0.0);
  for (int j = 0; j < cells; ++j)
    for (int i = 0; i < cells; ++i) {
      const int a = j * (cells + 1) + i;
      io::Face f1, f2;
      f1.v[0] = a, f1.v[1] = a + 1, f1.v[2] = a + cells + 2, f1.material = 0;
      f2.v[0] = a, f2.v[1] = a + cells + 2, f2.v[2] = a + cells + 1, f2.material = 0;
      m.faces.push_back(f1);
      m.faces.push_back(f2);
    }
  return m;
}

struct Scene {
  core::Camera camera = core::Camera::Pinhole(480, 270, 415.7);
  core::Pose pose = core::Pose::LookAt({0, -300, 25}, {0, 0, -40});  // ~12° down: horizon in the frame
  io::TexturedMesh truth = Ground(3000, -3000, 60);
  render::RenderResult frame;
  Scene() {
    const render::Renderer r(truth);
    render::RenderOptions o;
    o.supersample = 1;
    frame = r.Render(camera, pose, o);
  }
  // Share of the ground pixels whose surface point has y >= y_from.
  double ShareBeyond(double y_from) const {
    size_t ground = 0, beyond = 0;
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u) {
        const float d = frame.depth.at<float>(v, u);
        if (!(d > 0)) continue;
        ++ground;
        const Eigen::Vector3d ray = camera.Unproject({u + 0.5, v + 0.5});
        const Eigen::Vector3d X = pose.R().transpose() * (ray * d - pose.t);
        beyond += X.y() >= y_from;
      }
    return static_cast<double>(beyond) / static_cast<double>(ground);
  }
};

TEST(Coverage, SkyMaskFindsTheSkyAboveTheHorizon) {
  const Scene s;
  const cv::Mat sky = SkyMask(s.frame.image);
  size_t agree = 0, n_sky = 0;
  for (int v = 0; v < sky.rows; ++v)
    for (int u = 0; u < sky.cols; ++u) {
      const bool truth_sky = !(s.frame.depth.at<float>(v, u) > 0);
      n_sky += truth_sky;
      agree += truth_sky == (sky.at<uint8_t>(v, u) != 0);
    }
  EXPECT_GT(n_sky, static_cast<size_t>(0.1 * sky.total()));  // the frame does hold sky
  EXPECT_GT(static_cast<double>(agree) / static_cast<double>(sky.total()), 0.98);
  // A nadir-like frame of ground only has no sky.
  const core::Pose down = core::Pose::LookAt({0, 0, 100}, {0, 1, 0});
  const render::Renderer r(s.truth);
  render::RenderOptions o;
  o.supersample = 1;
  EXPECT_EQ(cv::countNonZero(SkyMask(r.Render(s.camera, down, o).image)), 0);
  EXPECT_THROW(SkyMask(cv::Mat()), Error);
}

TEST(Coverage, MeshAndCloudSharesMatchTheTrueGeometry) {
  const Scene s;
  // The whole ground: every non-sky pixel covered, but for a few rows of haze between the ground's far edge
  // and the horizon, where the blurred gradient of the edge keeps the sky mask out (measured 97.8%).
  const ViewCoverage full = ComputeViewCoverage(s.frame.image, s.camera, s.pose, &s.truth, nullptr, 0);
  EXPECT_GT(full.mesh, 0.97);
  EXPECT_EQ(full.dense, -1);
  // Only the ground from y = -150 on: the frame's near part is left out.
  const double y_from = -150;
  const double expected = s.ShareBeyond(y_from);
  ASSERT_GT(expected, 0.2);
  ASSERT_LT(expected, 0.95);
  const io::TexturedMesh part = Ground(3000, y_from, 60);
  io::OrientedPointCloud cloud;
  for (double y = y_from; y < 3000; y += (y < 300 ? 0.5 : 5))
    for (double x = -1500; x <= 1500; x += (y < 300 ? 0.5 : 5)) cloud.positions.emplace_back(x, y, 0.0);
  CoverageMaps maps;
  const ViewCoverage vc = ComputeViewCoverage(s.frame.image, s.camera, s.pose, &part, &cloud, 0.5, &maps);
  EXPECT_NEAR(vc.mesh, expected, 0.03);
  EXPECT_NEAR(vc.dense, expected, 0.06);
  EXPECT_EQ(vc.non_sky_pixels + vc.sky_pixels, static_cast<size_t>(s.camera.width * s.camera.height));
  ASSERT_FALSE(maps.mesh.empty());
  ASSERT_FALSE(maps.dense.empty());
  // A frame of another size is resized to the camera's.
  cv::Mat big;
  cv::resize(s.frame.image, big, cv::Size(960, 540));
  EXPECT_NEAR(ComputeViewCoverage(big, s.camera, s.pose, &part, nullptr, 0).mesh, expected, 0.03);
}

}  // namespace
}  // namespace fmv3d::pipeline
