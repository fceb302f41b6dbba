// Poisson reconstruction and its clean-up on analytic shapes, the mesh PLY round trip, and the errors on
// unusable clouds.
#include "fmv3d/surface/poisson.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/surface/colored_mesh.h"
#include "test_util.h"

namespace fmv3d::surface {
namespace {

// Points on a sphere (radius r at the origin), outward normals, colour by hemisphere.
io::OrientedPointCloud Sphere(int n, double r, double noise, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  io::OrientedPointCloud c;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d{g(rng), g(rng), g(rng)}.normalized();
    c.positions.push_back(r * d + noise * Eigen::Vector3d{g(rng), g(rng), g(rng)});
    c.normals.push_back(d.cast<float>());
    c.colors.push_back(d.z() > 0 ? io::Rgb8(200, 40, 40) : io::Rgb8(40, 40, 200));
  }
  return c;
}

TEST(Poisson, SphereIsAccurateOutwardAndColoured) {
  const auto cloud = Sphere(20000, 2.0, 0.0, 1);
  nlohmann::json stats;
  PoissonOptions opt;
  opt.density_quantile = 0;  // a closed, evenly sampled surface has no membrane to trim
  const ColoredMesh mesh = ReconstructPoisson(cloud, opt, &stats);
  ASSERT_FALSE(mesh.empty());
  EXPECT_GE(stats["depth"].get<int>(), 6);
  // Radius error of every vertex.
  double worst = 0;
  for (const auto& v : mesh.vertices) worst = std::max(worst, std::abs(v.norm() - 2.0));
  EXPECT_LT(worst, 0.03);
  EXPECT_NEAR(mesh.SurfaceArea(), 4 * M_PI * 4, 0.03 * 4 * M_PI * 4);
  // Faces wound outwards (normals agree with the input normals).
  int outward = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d n =
        (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    outward += n.dot(mesh.vertices[t[0]]) > 0;
  }
  EXPECT_EQ(outward, static_cast<int>(mesh.triangles.size()));
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    if (mesh.vertices[i].z() > 0.5) {
      EXPECT_GT(mesh.colors[i][0], 150);
    }
    if (mesh.vertices[i].z() < -0.5) {
      EXPECT_GT(mesh.colors[i][2], 150);
    }
  }
}

TEST(Poisson, InwardNormalsGiveInwardFaces) {
  auto cloud = Sphere(8000, 1.0, 0.0, 2);
  for (auto& n : cloud.normals) n = -n;
  PoissonOptions opt;
  opt.depth = 6;
  const ColoredMesh mesh = ReconstructPoisson(cloud, opt);
  ASSERT_FALSE(mesh.empty());
  int inward = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d n =
        (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
    inward += n.dot(mesh.vertices[t[0]]) < 0;
  }
  EXPECT_GT(inward, 0.99 * mesh.triangles.size());
}

// An open surface (a noisy square patch of a plane): Poisson closes it with a membrane, which trimming must
// remove, and the crop keeps the mesh within the points' footprint.
TEST(Poisson, OpenPlaneIsTrimmedToThePoints) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  std::normal_distribution<double> g(0, 0.01);
  io::OrientedPointCloud cloud;
  for (int i = 0; i < 30000; ++i) {
    cloud.positions.push_back({u(rng), u(rng), g(rng)});
    cloud.normals.emplace_back(0, 0, 1);
  }
  nlohmann::json stats;
  const ColoredMesh mesh = ReconstructPoisson(cloud, PoissonOptions{}, &stats);
  ASSERT_FALSE(mesh.empty());
  double worst_z = 0;
  for (const auto& v : mesh.vertices) {
    worst_z = std::max(worst_z, std::abs(v.z()));
    EXPECT_LE(std::abs(v.x()), 5.0 + 0.3);
    EXPECT_LE(std::abs(v.y()), 5.0 + 0.3);
  }
  EXPECT_LT(worst_z, 0.1);  // no closing membrane left above or below
  EXPECT_NEAR(mesh.SurfaceArea(), 100.0, 6.0);
  EXPECT_TRUE(mesh.colors.empty());
}

TEST(Poisson, DecimatesToTheTargetFaceCount) {
  const auto cloud = Sphere(20000, 1.0, 0.0, 4);
  PoissonOptions opt;
  opt.target_faces = 2000;
  const ColoredMesh mesh = ReconstructPoisson(cloud, opt);
  EXPECT_LE(mesh.triangles.size(), 2000u);
  EXPECT_GE(mesh.triangles.size(), 1800u);
  EXPECT_EQ(mesh.colors.size(), mesh.vertices.size());
  double worst = 0;
  for (const auto& v : mesh.vertices) worst = std::max(worst, std::abs(v.norm() - 1.0));
  EXPECT_LT(worst, 0.03);
}

TEST(Poisson, DepthFollowsThePointSpacing) {
  // A 100 m box of points 0.1 m apart wants cells ~0.2 m: 110 / 0.2 = 550 ≈ 2^9.1 → depth 9.
  PoissonOptions opt;
  Eigen::AlignedBox3d box(Eigen::Vector3d::Zero(), Eigen::Vector3d(100, 100, 30));
  EXPECT_EQ(AutomaticDepth(box, 0.1, opt), 9);
  EXPECT_EQ(AutomaticDepth(box, 0.05, opt), 10);
  EXPECT_EQ(AutomaticDepth(box, 10.0, opt), opt.min_depth);
  EXPECT_EQ(AutomaticDepth(box, 1e-4, opt), opt.max_depth);
  // Spacing of a regular 0.5 m grid.
  std::vector<Eigen::Vector3d> grid;
  for (int i = 0; i < 60; ++i)
    for (int j = 0; j < 60; ++j) grid.emplace_back(0.5 * i, 0.5 * j, 0);
  EXPECT_NEAR(MedianPointSpacing(grid), 0.5, 0.1);
}

TEST(Poisson, RejectsUnusableClouds) {
  io::OrientedPointCloud empty;
  EXPECT_THROW(ReconstructPoisson(empty, PoissonOptions{}), Error);
  auto no_normals = Sphere(1000, 1.0, 0.0, 5);
  no_normals.normals.clear();
  try {
    ReconstructPoisson(no_normals, PoissonOptions{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no normals"), std::string::npos);
  }
  PoissonOptions bad;
  bad.density_quantile = 0.95;
  EXPECT_THROW(bad.Check(), Error);
}

TEST(ColoredMesh, PlyRoundTrip) {
  test::TempDir dir;
  ColoredMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  m.colors = {io::Rgb8(1, 2, 3), io::Rgb8(250, 0, 0), io::Rgb8(0, 250, 0), io::Rgb8(0, 0, 250)};
  m.ComputeVertexNormals();
  WriteMeshPly(m, dir / "m.ply");
  const ColoredMesh r = ReadMeshPly(dir / "m.ply");
  ASSERT_EQ(r.vertices.size(), 4u);
  ASSERT_EQ(r.triangles.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_LT((r.vertices[i] - m.vertices[i]).norm(), 1e-6);
    EXPECT_EQ(r.colors[i], m.colors[i]);
    EXPECT_LT((r.normals[i] - m.normals[i]).norm(), 1e-5);
    EXPECT_EQ(r.triangles[i], m.triangles[i]);
  }
  EXPECT_THROW(ReadMeshPly(dir / "missing.ply"), Error);
}

}  // namespace
}  // namespace fmv3d::surface
