#include "fmv3d/geometry/mesh_distance.h"

#include <gtest/gtest.h>

#include <random>

namespace fmv3d::geometry {
namespace {

// Unit cube with outward counter-clockwise faces.
MeshDistance Cube() {
  std::vector<Eigen::Vector3d> v;
  v.reserve(8);
  for (int i = 0; i < 8; ++i) v.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  std::vector<Eigen::Vector3i> t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                                    {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return {v, t};
}

double CubeDistance(const Eigen::Vector3d& p) {
  const Eigen::Vector3d q = p.cwiseMax(0.0).cwiseMin(1.0);
  if (q != p) return (q - p).norm();
  const double inside = std::min({p.x(), p.y(), p.z(), 1 - p.x(), 1 - p.y(), 1 - p.z()});
  return inside;
}

TEST(MeshDistance, MatchesAnalyticCubeDistanceAndSign) {
  const MeshDistance cube = Cube();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 2.0);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p{u(rng), u(rng), u(rng)};
    const ClosestPoint c = cube.Closest(p);
    ASSERT_NEAR(c.distance, CubeDistance(p), 1e-12) << p.transpose();
    const bool inside = (p.array() > 0).all() && (p.array() < 1).all();
    if (c.distance > 1e-9) EXPECT_EQ(c.signed_distance < 0, inside) << p.transpose();
    EXPECT_NEAR((c.point - p).norm(), c.distance, 1e-12);
  }
}

TEST(MeshDistance, MaxDistancePrunes) {
  const MeshDistance cube = Cube();
  EXPECT_EQ(cube.Closest({5, 5, 5}, 1.0).face, -1);
  EXPECT_NEAR(cube.Closest({1.5, 0.5, 0.5}, 1.0).distance, 0.5, 1e-12);
}

TEST(MeshDistance, SamplesCoverTheSurfaceAtTheSpacing) {
  const MeshDistance cube = Cube();
  std::vector<int> faces;
  const auto s = cube.SampleSurface(0.05, &faces);
  EXPECT_NEAR(static_cast<double>(s.size()), 6 / 0.0025, 6 / 0.0025 * 0.05);
  ASSERT_EQ(faces.size(), s.size());
  for (const auto& p : s) EXPECT_LT(cube.Closest(p).distance, 1e-12);
}

}  // namespace
}  // namespace fmv3d::geometry
