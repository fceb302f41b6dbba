// The mesh stage's memory model and the Poisson depth it allows under `--max-memory` (poisson_budget.h).
#include "fmv3d/surface/poisson_budget.h"

#include <gtest/gtest.h>

#include <algorithm>
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
  const PoissonMemoryModel m{100, 1000, 50, 20};
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(0, 0, m), 0);
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(10, 3, m), 4000);
  EXPECT_DOUBLE_EQ(EstimatePoissonBytes(20, 6, m), 2 * EstimatePoissonBytes(10, 3, m));
  // Averaged: the cloud's own bytes, then the larger of the spacing's tree and the solver's points and cells.
  EXPECT_DOUBLE_EQ(EstimateAveragedPoissonBytes(1000, 5000, 100, 3, m), 5000 + 20000);
  EXPECT_DOUBLE_EQ(EstimateAveragedPoissonBytes(1000, 5000, 100, 30, m), 5000 + 5000 + 30000);
}

TEST(PoissonBudget, ResidentBytesCountTheVisibilityLists) {
  io::OrientedPointCloud c;
  c.positions.assign(10, Eigen::Vector3d::Zero());
  c.normals.assign(10, Eigen::Vector3f::UnitZ());
  c.positions.shrink_to_fit();
  c.normals.shrink_to_fit();
  const double bare = ResidentBytes(c);
  EXPECT_DOUBLE_EQ(bare, 10 * (24 + 12));
  c.visibility.assign(10, std::vector<uint32_t>(20, 1));  // 80 B each: a 96 B heap chunk
  c.visibility.shrink_to_fit();
  EXPECT_DOUBLE_EQ(ResidentBytes(c), bare + 10 * (sizeof(std::vector<uint32_t>) + 96));
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
  const PoissonMemoryModel m{100, 1000, 50, 20};
  std::vector<int> asked;
  auto cells = [&](int d) {  // a surface: 4x the cells per level
    asked.push_back(d);
    return static_cast<size_t>(std::pow(4.0, d));
  };
  const size_t points = 10000;  // 0.95 MB
  // 100 MB: 4^8 = 65,536 cells (63.5 MB) fit, 4^9 (251 MB) do not.
  PoissonDepthChoice c = ChoosePoissonDepth(10, 6, points, 1e5, 100, cells, m);
  EXPECT_EQ(c.depth, 8);
  EXPECT_TRUE(c.lowered);
  EXPECT_FALSE(c.over_budget);
  EXPECT_EQ(c.occupied_cells, 65536u);
  EXPECT_NEAR(c.estimated_mb, (1e6 + 65536e3) / 1048576.0, 1e-9);
  // Every depth's quarter and half cells hold more cells than there are points: averaging would not thin them.
  EXPECT_EQ(asked, (std::vector<int>{10, 12, 11, 9, 8}));
  EXPECT_EQ(c.average_depth, 0);
  // A budget the wanted depth fits, and no budget: the wanted depth, not lowered.
  for (double budget : {2048.0, 0.0}) {
    c = ChoosePoissonDepth(10, 6, points, 1e5, budget, cells, m);
    EXPECT_EQ(c.depth, 10) << budget;
    EXPECT_FALSE(c.lowered) << budget;
  }
  // Below even the point term: min_depth, flagged.
  c = ChoosePoissonDepth(10, 6, points, 1e5, 0.5, cells, m);
  EXPECT_EQ(c.depth, 6);
  EXPECT_TRUE(c.lowered);
  EXPECT_TRUE(c.over_budget);
}

// A cloud far denser than the cells: averaging in half cells fits the wanted depth, which the points alone do not.
TEST(PoissonBudget, AveragesThePointsBeforeLoweringTheDepth) {
  const PoissonMemoryModel m{300, 1000, 200, 60};
  auto cells = [](int d) { return static_cast<size_t>(std::pow(4.0, d)); };
  const size_t points = 1000000;  // 286 MB at 300 B: over 200 MB at any depth
  // Depth 8: 65,536 cells (62.5 MB); quarter cells (depth 10) 1.05 M, more than the points; half cells 262,144
  // points (50 MB); the cloud 40 MB; the spacing tree 57 MB.
  PoissonDepthChoice c = ChoosePoissonDepth(8, 5, points, 40 * 1048576.0, 200, cells, m);
  EXPECT_EQ(c.depth, 8);
  EXPECT_FALSE(c.lowered);
  EXPECT_EQ(c.average_depth, 9);
  EXPECT_EQ(c.averaged_points, 262144u);
  EXPECT_NEAR(c.estimated_mb, 40 + (262144 * 200.0 + 65536 * 1000.0) / 1048576.0, 1e-9);
  // A budget that depth 8 does not fit: depth 7, averaged in its quarter cells (depth 9: 262,144 points, 105.6 MB).
  c = ChoosePoissonDepth(8, 5, points, 40 * 1048576.0, 110, cells, m);
  EXPECT_EQ(c.depth, 7);
  EXPECT_TRUE(c.lowered);
  EXPECT_EQ(c.average_depth, 9);
  EXPECT_NEAR(c.estimated_mb, 40 + (262144 * 200.0 + 16384 * 1000.0) / 1048576.0, 1e-9);
  // ... and one only its half cells fit (depth 8: 65,536 points, the spacing tree's 97.2 MB).
  c = ChoosePoissonDepth(8, 5, points, 40 * 1048576.0, 100, cells, m);
  EXPECT_EQ(c.depth, 7);
  EXPECT_EQ(c.average_depth, 8);
  EXPECT_NEAR(c.estimated_mb, 40 + 60e6 / 1048576.0, 1e-9);
  // Below the cloud and its spacing tree: nothing fits; min_depth, averaged (the smaller estimate), flagged.
  c = ChoosePoissonDepth(8, 5, points, 40 * 1048576.0, 50, cells, m);
  EXPECT_EQ(c.depth, 5);
  EXPECT_TRUE(c.over_budget);
  EXPECT_EQ(c.average_depth, 7);
  EXPECT_NEAR(c.estimated_mb, 40 + 60e6 / 1048576.0, 1e-9);
}

TEST(PoissonBudget, AverageInCellsMergesEachCellsPoints) {
  io::OrientedPointCloud c;
  // Box 0..10 (cube 11, centred: origin -0.5); depth 1 → cells of 5.5 split at x = 5.
  auto add = [&](const Eigen::Vector3d& p, const Eigen::Vector3f& n, const io::Rgb8& rgb) {
    c.positions.push_back(p);
    c.normals.push_back(n);
    c.colors.push_back(rgb);
  };
  add({0, 0, 0}, {0, 0, 1}, {0, 0, 0});
  add({2, 0, 0}, {0, 1, 0}, {255, 0, 0});
  add({8, 0, 0}, {0, 0, 1}, {0, 255, 0});  // a sheet seen from both sides: its normals cancel
  add({9, 0, 0}, {0, 0, -1}, {0, 255, 0});
  add({10, 10, 10}, {1, 0, 0}, {0, 0, 255});
  add({5, 5, 5}, {1, 0, 0}, {0, 0, 255});  // left out by the index list
  const Eigen::AlignedBox3d box(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(10, 10, 10));
  const CellAverages a = AverageInCells(c, {0, 1, 2, 3, 4}, box, 1);
  ASSERT_EQ(a.points.size(), 3u);
  ASSERT_EQ(a.normals.size(), 3u);
  ASSERT_EQ(a.colors.size(), 3u);
  // Sorted by cell key (x major): the cell at the origin, the one at x ≥ 5, the far corner.
  EXPECT_TRUE(a.points[0].isApprox(Eigen::Vector3d(1, 0, 0)));
  EXPECT_TRUE(a.normals[0].isApprox(Eigen::Vector3d(0, 1, 1).normalized()));
  EXPECT_TRUE(a.colors[0].isApprox(Eigen::Vector3d(0.5, 0, 0)));
  EXPECT_TRUE(a.points[1].isApprox(Eigen::Vector3d(8.5, 0, 0)));
  EXPECT_TRUE(a.normals[1].isApprox(Eigen::Vector3d(0, 0, 1)));  // the first point's
  EXPECT_TRUE(a.points[2].isApprox(Eigen::Vector3d(10, 10, 10)));
  EXPECT_EQ(a.points.size(), OccupiedCells({{0, 0, 0}, {2, 0, 0}, {8, 0, 0}, {9, 0, 0}, {10, 10, 10}}, box, 1));
  EXPECT_TRUE(AverageInCells(c, {}, box, 1).points.empty());
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

// Radius error of the worst vertex of a unit sphere's mesh.
double WorstRadiusError(const ColoredMesh& mesh) {
  double worst = 0;
  for (const auto& v : mesh.vertices) worst = std::max(worst, std::abs(v.norm() - 1.0));
  return worst;
}

// The default budget leaves a small cloud's surface exactly as without a budget; a budget just below the
// wanted depth's estimate averages the points instead (same depth, as accurate); one below that gives a coarser
// depth, reported.
TEST(PoissonBudget, ReconstructionRespectsTheBudget) {
  const auto cloud = Sphere(50000);
  PoissonOptions opt;
  opt.kind = SurfaceKind::kWatertight;
  opt.min_depth = 3;
  opt.depth = 5;  // cells ~4x the point spacing: ~4 points per half cell
  nlohmann::json free_stats, default_stats, tight_stats;
  opt.max_memory_mb = 0;
  const ColoredMesh free_mesh = ReconstructPoisson(cloud, opt, &free_stats);
  EXPECT_EQ(free_stats["solver_points"], cloud.size());
  opt.max_memory_mb = PoissonOptions{}.max_memory_mb;
  const ColoredMesh default_mesh = ReconstructPoisson(cloud, opt, &default_stats);
  EXPECT_EQ(default_stats["memory"]["lowered_by_budget"], false);
  EXPECT_EQ(default_stats["memory"]["averaged_in_depth"], 0);
  EXPECT_EQ(default_mesh.vertices, free_mesh.vertices);
  EXPECT_EQ(default_mesh.triangles, free_mesh.triangles);

  // Tighter and tighter budgets: the points are averaged in coarser and coarser cells at the wanted depth before
  // the depth is lowered; every surface within its budget, the averaged ones as accurate as every point's.
  Eigen::AlignedBox3d box;
  for (const auto& p : cloud.positions) box.extend(p);
  double budget = free_stats["memory"]["estimated_mb"].get<double>();
  std::vector<int> averaged_in;
  for (int step = 0; step < 10; ++step) {
    budget *= 0.99;
    opt.max_memory_mb = budget;
    const ColoredMesh mesh = ReconstructPoisson(cloud, opt, &tight_stats);
    ASSERT_FALSE(mesh.empty());
    EXPECT_LE(tight_stats["memory"]["estimated_mb"].get<double>(), budget);
    if (tight_stats["depth"] != 5) break;
    const int average = tight_stats["memory"]["averaged_in_depth"];
    ASSERT_GT(average, 5);
    averaged_in.push_back(average);
    const size_t solver_points = tight_stats["solver_points"];
    EXPECT_EQ(solver_points, OccupiedCells(cloud.positions, box, average));
    EXPECT_LT(solver_points, cloud.size());
    EXPECT_LT(WorstRadiusError(mesh), 1.2 * WorstRadiusError(free_mesh) + 1e-3);
    budget = tight_stats["memory"]["estimated_mb"].get<double>();
  }
  ASSERT_FALSE(averaged_in.empty());
  EXPECT_TRUE(std::is_sorted(averaged_in.rbegin(), averaged_in.rend()));
  EXPECT_EQ(averaged_in.back(), 6);
  EXPECT_EQ(tight_stats["depth"], 4);
  EXPECT_EQ(tight_stats["memory"]["depth_wanted"], 5);
  EXPECT_EQ(tight_stats["memory"]["lowered_by_budget"], true);
  EXPECT_NEAR(tight_stats["cell_width"].get<double>(), 2 * free_stats["cell_width"].get<double>(),
              0.02 * free_stats["cell_width"].get<double>());
  // A budget below the cloud itself: min_depth, flagged over budget.
  opt.max_memory_mb = 0.5;
  ReconstructPoisson(cloud, opt, &tight_stats);
  EXPECT_EQ(tight_stats["depth"], opt.min_depth);
  EXPECT_EQ(tight_stats["memory"]["over_budget"], true);
}

}  // namespace
}  // namespace fmv3d::surface
