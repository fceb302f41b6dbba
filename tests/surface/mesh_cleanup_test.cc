// Which connected pieces of a Poisson surface are kept: every piece the dense points support (terrain and
// each separate building), none fitted to a few outliers; the watertight option keeps the surface closed.
#include "fmv3d/surface/mesh_cleanup.h"

#include <gtest/gtest.h>

#include <map>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/surface/poisson.h"

namespace fmv3d::surface {
namespace {

// Points with outward normals on the walls and roof of an axis-aligned box (no floor: it stands on ground).
void AddBuilding(io::OrientedPointCloud* c, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double spacing,
                 std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0, 0.1 * spacing);
  auto add = [&](const Eigen::Vector3d& p, const Eigen::Vector3f& n) {
    c->positions.push_back(p + Eigen::Vector3d{noise(rng), noise(rng), noise(rng)});
    c->normals.push_back(n);
  };
  for (double x = lo.x(); x <= hi.x(); x += spacing)
    for (double y = lo.y(); y <= hi.y(); y += spacing) add({x, y, hi.z()}, {0, 0, 1});
  for (double z = lo.z(); z < hi.z(); z += spacing) {
    for (double x = lo.x(); x <= hi.x(); x += spacing) {
      add({x, lo.y(), z}, {0, -1, 0});
      add({x, hi.y(), z}, {0, 1, 0});
    }
    for (double y = lo.y(); y <= hi.y(); y += spacing) {
      add({lo.x(), y, z}, {-1, 0, 0});
      add({hi.x(), y, z}, {1, 0, 0});
    }
  }
}

// A gently undulating terrain patch over [x0, x1] × [y0, y1], normals up.
void AddTerrain(io::OrientedPointCloud* c, double x0, double x1, double y0, double y1, double spacing) {
  for (double x = x0; x <= x1; x += spacing)
    for (double y = y0; y <= y1; y += spacing) {
      c->positions.emplace_back(x, y, 0.3 * std::sin(x / 7) * std::cos(y / 9));
      c->normals.emplace_back(0, 0, 1);
    }
}

// Share of the points within `tol` of the mesh.
double CoveredShare(const ColoredMesh& mesh, const std::vector<Eigen::Vector3d>& pts, double tol) {
  const geometry::MeshDistance md(mesh.vertices, mesh.triangles);
  size_t n = 0;
  for (const auto& p : pts) n += md.Closest(p).distance <= tol;
  return static_cast<double>(n) / static_cast<double>(pts.size());
}

// A town: terrain on one side, five buildings apart from it and from each other (no ground sampled between
// them, as when their feet are hidden), one of them far smaller than the terrain; plus three tight clusters
// of outlier points floating in the air. Every building and the terrain must survive whole; the outlier
// blobs must not.
TEST(MeshCleanup, KeepsTerrainAndEverySeparateBuildingDropsOutlierBlobs) {
  std::mt19937_64 rng(5);
  io::OrientedPointCloud cloud;
  const double s = 0.25;
  AddTerrain(&cloud, -40, 40, -40, -5, s);
  const std::vector<Eigen::Vector3d> terrain_points = cloud.positions;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> buildings = {{{-35, 5, 0}, {-25, 15, 12}},
                                                                        {{-15, 8, 0}, {-5, 14, 8}},
                                                                        {{5, 5, 0}, {15, 20, 20}},
                                                                        {{25, 10, 0}, {33, 18, 6}},
                                                                        {{-30, 28, 0}, {-26, 32, 4}}};
  std::vector<std::vector<Eigen::Vector3d>> building_points;
  for (const auto& [lo, hi] : buildings) {
    const size_t before = cloud.size();
    AddBuilding(&cloud, lo, hi, s, rng);
    building_points.emplace_back(cloud.positions.begin() + static_cast<std::ptrdiff_t>(before), cloud.positions.end());
  }
  std::normal_distribution<double> g(0, 0.15);
  for (const Eigen::Vector3d& c :
       {Eigen::Vector3d(0, -20, 15), Eigen::Vector3d(20, 30, 25), Eigen::Vector3d(-10, 25, 30)})
    for (int i = 0; i < 12; ++i) {
      cloud.positions.push_back(c + Eigen::Vector3d{g(rng), g(rng), g(rng)});
      cloud.normals.push_back(Eigen::Vector3d{g(rng), g(rng), 1}.normalized().cast<float>());
    }

  nlohmann::json stats;
  const ColoredMesh mesh = ReconstructPoisson(cloud, PoissonOptions{}, &stats);
  EXPECT_GE(stats["components"]["kept"].get<size_t>(), 6u) << stats.dump(1);
  // The terrain and every building are there, whole.
  EXPECT_GT(CoveredShare(mesh, terrain_points, 3 * s), 0.97);
  for (size_t b = 0; b < building_points.size(); ++b)
    EXPECT_GT(CoveredShare(mesh, building_points[b], 3 * s), 0.95) << "building " << b;
  // Nothing left near the outlier clusters.
  const geometry::MeshDistance md(mesh.vertices, mesh.triangles);
  for (const Eigen::Vector3d& c :
       {Eigen::Vector3d(0, -20, 15), Eigen::Vector3d(20, 30, 25), Eigen::Vector3d(-10, 25, 30)})
    EXPECT_GT(md.Closest(c).distance, 1.0);
}

// The rule itself on hand-made pieces: two supported squares of very different size are both kept (rank
// does not matter), an unsupported one and a tiny supported one are not.
TEST(MeshCleanup, DecidesPerPieceOnSupportAndArea) {
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  auto square = [&](const Eigen::Vector3d& o, double size, int n) {  // n x n cells of a grid
    const int base = static_cast<int>(v.size());
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) v.push_back(o + Eigen::Vector3d(size * i / n, size * j / n, 0));
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int a = base + j * (n + 1) + i;
        t.emplace_back(a, a + 1, a + n + 2);
        t.emplace_back(a, a + n + 2, a + n + 1);
      }
  };
  const double cell = 0.5, spacing = 0.25;
  square({0, 0, 0}, 100, 200);  // the big one: 10000 m²
  square({200, 0, 0}, 5, 10);   // a small building roof: 25 m² = 100 cells²
  square({300, 0, 0}, 20, 40);  // a piece with no points
  square({400, 0, 0}, 1.5, 3);  // 2.25 m² = 9 cells², 49 points: an outlier blob
  std::vector<Eigen::Vector3d> pts;
  auto sample = [&](const Eigen::Vector3d& o, double size) {
    for (double y = 0; y <= size; y += spacing)
      for (double x = 0; x <= size; x += spacing) pts.push_back(o + Eigen::Vector3d(x, y, 0.05));
  };
  sample({0, 0, 0}, 100);
  sample({200, 0, 0}, 5);
  sample({400, 0, 0}, 1.5);
  const ComponentSelection sel = SelectComponents(v, t, pts, cell, spacing, ComponentOptions{});
  ASSERT_EQ(sel.components.size(), 4u);
  EXPECT_EQ(sel.components[0].decision, ComponentDecision::kKept);
  EXPECT_EQ(sel.components[1].decision, ComponentDecision::kKept);
  EXPECT_EQ(sel.components[2].decision, ComponentDecision::kTooFewPoints);
  EXPECT_EQ(sel.components[3].decision, ComponentDecision::kTooSmall);
  EXPECT_EQ(sel.kept(), 2u);
  EXPECT_NEAR(sel.components[1].area, 25.0, 1e-9);
  EXPECT_NEAR(static_cast<double>(sel.components[1].support), 21.0 * 21.0, 1.0);
  EXPECT_EQ(sel.kept_faces(), 2u * 200 * 200 + 2u * 10 * 10);
  EXPECT_NEAR(static_cast<double>(sel.components[3].support), 7.0 * 7.0, 1.0);
  // Without points, only the piece with the most support (all have none: the first) is kept.
  const ComponentSelection none = SelectComponents(v, t, {}, cell, spacing, ComponentOptions{});
  EXPECT_EQ(none.kept(), 1u);
  EXPECT_THROW(SelectComponents(v, t, pts, 0, spacing, ComponentOptions{}), Error);
  std::vector<Eigen::Vector3i> bad = {{0, 1, static_cast<int>(v.size())}};
  EXPECT_THROW(SelectComponents(v, bad, pts, cell, spacing, ComponentOptions{}), Error);
}

// Watertight: an object's surface stays closed (every edge shared by exactly two faces); open: a plane's
// membrane is trimmed away.
TEST(MeshCleanup, WatertightKeepsTheSurfaceClosed) {
  std::mt19937_64 rng(9);
  std::normal_distribution<double> g(0, 1);
  io::OrientedPointCloud cloud;
  for (int i = 0; i < 15000; ++i) {
    Eigen::Vector3d d{g(rng), g(rng), g(rng)};
    d.normalize();
    // A hemisphere's worth of dense points and a sparser far side: still one closed object.
    if (d.z() < 0 && i % 3 != 0) continue;
    cloud.positions.push_back(1.5 * d);
    cloud.normals.push_back(d.cast<float>());
  }
  PoissonOptions opt;
  opt.kind = SurfaceKind::kWatertight;
  nlohmann::json stats;
  const ColoredMesh mesh = ReconstructPoisson(cloud, opt, &stats);
  std::map<std::pair<int, int>, int> edges;
  for (const auto& f : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const int a = f[k], b = f[(k + 1) % 3];
      edges[{std::min(a, b), std::max(a, b)}]++;
    }
  size_t boundary = 0;
  for (const auto& [e, n] : edges) boundary += n != 2;
  EXPECT_EQ(boundary, 0u);
  EXPECT_EQ(stats["kind"], "watertight");
  EXPECT_NEAR(mesh.SurfaceArea(), 4 * M_PI * 1.5 * 1.5, 0.05 * 4 * M_PI * 1.5 * 1.5);
}

}  // namespace
}  // namespace fmv3d::surface
