// The report's picture of an untextured (Poisson) surface: shaded so its shape reads, never blown out to white.
#include "fmv3d/pipeline/preview.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace fmv3d::pipeline {
namespace {

// A 20 m x 20 m level square with a 5 m ridge along y = 0, seen from 40 m away and 8 m up (a low viewer, as the
// report's oblique view of a flat site is).
TEST(Preview, UntexturedSurfaceFacingALowViewerIsShadedNotSaturated) {
  io::TexturedMesh mesh;
  const int n = 20;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = i - n / 2.0, y = j - n / 2.0;
      mesh.vertices.emplace_back(x, y, 5 * std::exp(-y * y / 8));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      io::Face f1, f2;
      f1.v[0] = a, f1.v[1] = b, f1.v[2] = d;
      f2.v[0] = a, f2.v[1] = d, f2.v[2] = c;
      mesh.faces.push_back(f1);
      mesh.faces.push_back(f2);
    }
  View view;
  view.camera.width = 320;
  view.camera.height = 240;
  view.camera.f = 300;
  view.camera.u0 = 160;
  view.camera.v0 = 120;
  const Eigen::Vector3d centre(0, -40, 8), target(0, 0, 1);
  const Eigen::Vector3d z = (target - centre).normalized(), x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d R;
  R.row(0) = x;
  R.row(1) = z.cross(x);
  R.row(2) = z;
  view.pose.q = Eigen::Quaterniond(R);
  view.pose.t = -R * centre;
  const cv::Mat img = RenderMesh(mesh, view);
  ASSERT_EQ(img.type(), CV_8UC3);
  // The surface fills the middle of the picture: its pixels are neither white nor one flat grey.
  cv::Mat grey;
  cv::cvtColor(img(cv::Rect(100, 100, 120, 60)), grey, cv::COLOR_BGR2GRAY);
  double lo = 0, hi = 0;
  cv::minMaxLoc(grey, &lo, &hi);
  EXPECT_LT(hi, 250);
  EXPECT_GT(hi - lo, 30);
}

}  // namespace
}  // namespace fmv3d::pipeline
