#include "fmv3d/core/camera.h"

#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::core {
namespace {

Camera RandomCamera(std::mt19937& rng, bool distorted) {
  std::uniform_real_distribution<double> U(-1, 1);
  Camera c = Camera::Pinhole(1280, 720, 900 + 300 * U(rng));
  c.aspect = 1 + 0.02 * U(rng);
  c.u0 += 20 * U(rng);
  c.v0 += 20 * U(rng);
  if (distorted) {
    c.k1 = 0.15 * U(rng);
    c.k2 = 0.02 * U(rng);
    c.p1 = 0.002 * U(rng);
    c.p2 = 0.002 * U(rng);
  }
  return c;
}

TEST(Camera, ProjectionAgreesWithOpenCV) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> U(-1, 1);
  double worst = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Camera c = RandomCamera(rng, trial % 4 != 0);
    std::vector<cv::Point3d> pts;
    std::vector<Eigen::Vector3d> eig;
    for (int i = 0; i < 50; ++i) {
      Eigen::Vector3d X{U(rng) * 5, U(rng) * 3, 8 + 4 * U(rng)};
      pts.emplace_back(X.x(), X.y(), X.z());
      eig.push_back(X);
    }
    // OpenCV puts pixel centres at integers; ours at +0.5 (camera.h), hence the half-pixel shift of (cx, cy).
    cv::Matx33d K(c.fx(), 0, c.u0 - 0.5, 0, c.fy(), c.v0 - 0.5, 0, 0, 1);
    std::vector<double> dist = {c.k1, c.k2, c.p1, c.p2, 0.0};
    std::vector<cv::Point2d> out;
    cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, dist, out);
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector2d uv = c.Project(eig[i]);
      worst = std::max(worst, (uv - Eigen::Vector2d(out[i].x + 0.5, out[i].y + 0.5)).norm());
    }
  }
  EXPECT_LT(worst, 1e-9);
}

TEST(Camera, UnprojectInvertsProjectInsideTheImage) {
  std::mt19937 rng(2);
  double worst_px = 0, worst_ray = 0;
  int checked = 0;
  for (int trial = 0; trial < 100; ++trial) {
    const Camera c = RandomCamera(rng, true);
    for (int j = -30; j <= 30; ++j)
      for (int i = -30; i <= 30; ++i) {
        const Eigen::Vector3d ray(i / 25.0, j / 25.0, 1.0);
        // A real lens maps radius monotonically over its field of view; beyond the fold there is no inverse.
        const double r2 = ray.head<2>().squaredNorm();
        if (1 + 3 * c.k1 * r2 + 5 * c.k2 * r2 * r2 < 0.2) continue;
        const Eigen::Vector2d uv = c.Project(ray * 2.5);
        if (!c.InImage(uv)) continue;
        const Eigen::Vector3d back = c.Unproject(uv);
        worst_ray = std::max(worst_ray, (back - ray).norm());
        worst_px = std::max(worst_px, (c.Project(back) - uv).norm());
        ++checked;
      }
  }
  EXPECT_GT(checked, 50000);
  EXPECT_LT(worst_px, 1e-10);
  EXPECT_LT(worst_ray, 1e-11);
}

TEST(Camera, JacobianMatchesFiniteDifferences) {
  std::mt19937 rng(3);
  const Camera c = RandomCamera(rng, true);
  const Eigen::Vector3d X(0.7, -0.4, 5.0);
  const auto J = c.ProjectJacobian(X);
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d[k] = 1e-6;
    const Eigen::Vector2d num = (c.Project(X + d) - c.Project(X - d)) / 2e-6;
    EXPECT_NEAR((num - J.col(k)).norm(), 0, 1e-4) << "column " << k;
  }
}

TEST(Camera, ValidateRejectsNonsense) {
  Camera c = Camera::Pinhole(640, 480, 500);
  EXPECT_NO_THROW(c.Validate());
  c.f = -1;
  EXPECT_THROW(c.Validate(), Error);
  c = Camera::Pinhole(0, 480, 500);
  EXPECT_THROW(c.Validate(), Error);
}

}  // namespace
}  // namespace fmv3d::core
