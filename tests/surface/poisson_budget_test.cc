// The mesh stage's memory model and the Poisson depth it allows under `--max-memory` (poisson_budget.h).
#include "fmv3d/surface/poisson_budget.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "fmv3d/surface/poisson.h"

namespace fmv3d::surface {
namespace {

// A 100 x 100 grid of points 1 m apart on z = 0: extent 99 m, Open3D's cube 108.9 m starting 4.95 m before x = 0.
std::vector<Eigen::Vector3d> Grid() {
  std::vector<Eigen::Vector3d> g;
  for (int i = 0; i < 100; ++i)
    for (int j = 0; j < 100; ++j) g.emplace_back(i, j, 0);
  return g;
}

Eigen::AlignedBox3d BoxOf(const std::vector<Eigen::Vector3d>& points) {
  Eigen::AlignedBox3d b;
  for (const auto& p : points) b.extend(p);
  return b;
}

TEST(PoissonBudget, OccupiedCellsOfAPlane) {
  const auto grid = Grid();
  const auto box = BoxOf(grid);
  // Depth 1: cells of 54.45 m, x from 4.95 to 103.95 → indices 0..1 on x and y, one layer in z.
  EXPECT_EQ(OccupiedCells(grid, box, 1), 4u);
  // Depth 3: cells of 13.61 m → indices 0..7 (103.95 / 13.61 = 7.6).
  EXPECT_EQ(OccupiedCells(grid, box, 3), 64u);
  // Depth 6: cells of 1.70 m, coarser than the spacing, so every cell of the square holds a point: indices 2..61
  // (4.95 / 1.70 = 2.9, 103.95 / 1.70 = 61.1) → 60 x 60.
  EXPECT_EQ(OccupiedCells(grid, box, 6), 60u * 60u);
  // Depth 8: cells of 0.43 m, finer than the spacing: one point per cell.
  EXPECT_EQ(OccupiedCells(grid, box, 8), grid.size());
  EXPECT_EQ(OccupiedCells({}, box, 5), 0u);
  EXPECT_EQ(OccupiedCells({Eigen::Vector3d(1, 2, 3)}, BoxOf({Eigen::Vector3d(1, 2, 3)}), 9), 1u);
}

TEST(PoissonBudget, EstimateIsLinear) {
  const PoissonMemoryModel m{100, 1000};
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(0, 0, m), 0);
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(10, 3, m), 4000);
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(20, 6, m), 2 * EstimatePoissonBytes(10, 3, m));
}

// The default constants are a bound: at or above every mesh-stage peak measured (above the process's base) on the
// two fitted clouds, bench/results/scale11.md and mem12.md: {points, occupied cells, MiB}.
TEST(PoissonBudget, DefaultModelCoversTheMeasuredRuns) {
  struct Run {
    size_t points, cells;
    double mib;
  };
  const Run runs[] = {{652935, 16271, 177.4},  {652935, 60684, 225.1},  {652935, 188005, 358.1},
                      {1042315, 16068, 280.9}, {1042315, 65876, 360.7}, {1042315, 274070, 642.7}};
  for (const Run& r : runs) {
    const double estimate_mib = EstimatePoissonBytes(r.points, r.cells, PoissonMemoryModel{}) / 1048576.0;
    EXPECT_GE(estimate_mib, r.mib) << r.points << " points, " << r.cells << " cells";
    EXPECT_LE(estimate_mib, 1.25 * r.mib) << r.points << " points, " << r.cells << " cells";
  }
}

TEST(PoissonBudget, LowersTheDepthUntilTheEstimateFits) {
  const PoissonMemoryModel m{100, 1000};
  std::vector<int> asked;
  auto cells = [&](int d) {  // a surface: 4x the cells per level
    asked.push_back(d);
    return static_cast<size_t>(std::pow(4.0, d));
  };
  const size_t points = 10000;  // 0.95 MB
  // 100 MB: 4^8 = 65,536 cells (63.5 MB) fit, 4^9 (251 MB) do not.
  PoissonDepthChoice c = ChoosePoissonDepth(10, 6, points, 100, cells, m);
  EXPECT_EQ(c.depth, 8);
  EXPECT_TRUE(c.lowered);
  EXPECT_FALSE(c.over_budget);
  EXPECT_EQ(c.occupied_cells, 65536u);
  EXPECT_NEAR(c.estimated_mb, (1e6 + 65536e3) / 1048576.0, 1e-9);
  EXPECT_EQ(asked, (std::vector<int>{10, 9, 8}));
  // A budget the wanted depth fits, and no budget: the wanted depth, not lowered.
  for (double budget : {2048.0, 0.0}) {
    c = ChoosePoissonDepth(10, 6, points, budget, cells, m);
    EXPECT_EQ(c.depth, 10) << budget;
    EXPECT_FALSE(c.lowered) << budget;
  }
  // Below even the point term: min_depth, flagged.
  c = ChoosePoissonDepth(10, 6, points, 0.5, cells, m);
  EXPECT_EQ(c.depth, 6);
  EXPECT_TRUE(c.lowered);
  EXPECT_TRUE(c.over_budget);
}

io::OrientedPointCloud Sphere(int n) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g(0, 1);
  io::OrientedPointCloud c;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d{g(rng), g(rng), g(rng)}.normalized();
    c.positions.push_back(d);
    c.normals.push_back(d.cast<float>());
  }
  return c;
}

// The default budget leaves a small cloud's surface exactly as without a budget; a budget just below the
// wanted depth's estimate gives the next coarser depth, reported.
TEST(PoissonBudget, ReconstructionRespectsTheBudget) {
  const auto cloud = Sphere(20000);
  PoissonOptions opt;
  opt.kind = SurfaceKind::kWatertight;
  opt.min_depth = 4;  // room below the automatic depth (6 here)
  nlohmann::json free_stats, default_stats, tight_stats;
  opt.max_memory_mb = 0;
  const ColoredMesh free_mesh = ReconstructPoisson(cloud, opt, &free_stats);
  opt.max_memory_mb = PoissonOptions{}.max_memory_mb;
  const ColoredMesh default_mesh = ReconstructPoisson(cloud, opt, &default_stats);
  EXPECT_EQ(default_stats["memory"]["lowered_by_budget"], false);
  EXPECT_EQ(default_mesh.vertices, free_mesh.vertices);
  EXPECT_EQ(default_mesh.triangles, free_mesh.triangles);

  const int wanted = free_stats["depth"];
  opt.max_memory_mb = 0.99 * free_stats["memory"]["estimated_mb"].get<double>();
  const ColoredMesh tight_mesh = ReconstructPoisson(cloud, opt, &tight_stats);
  EXPECT_EQ(tight_stats["depth"], wanted - 1);
  EXPECT_EQ(tight_stats["memory"]["depth_wanted"], wanted);
  EXPECT_EQ(tight_stats["memory"]["lowered_by_budget"], true);
  EXPECT_LE(tight_stats["memory"]["estimated_mb"].get<double>(), opt.max_memory_mb);
  EXPECT_NEAR(tight_stats["cell_width"].get<double>(), 2 * free_stats["cell_width"].get<double>(), 1e-12);
  EXPECT_FALSE(tight_mesh.empty());
  // A budget below the point term: min_depth, flagged over budget.
  opt.max_memory_mb = 0.5;
  ReconstructPoisson(cloud, opt, &tight_stats);
  EXPECT_EQ(tight_stats["depth"], opt.min_depth);
  EXPECT_EQ(tight_stats["memory"]["over_budget"], true);
}

}  // namespace
}  // namespace fmv3d::surface
