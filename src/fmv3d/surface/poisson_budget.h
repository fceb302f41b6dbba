// Memory of the mesh stage, and the Poisson depth that keeps it within `--max-memory`.
//
// The stage's peak is the point arrays (the cloud as read, Open3D's copy with double normals and colours, the
// k-d tree, the solver's samples) plus Kazhdan's octree, whose nodes are refined around the samples: the finest
// level has about one node per octree cell that holds a point, and the coarser levels and the B-spline support
// around each add a constant factor. So the model is linear in the points and in the occupied cells at the
// depth:   bytes ≈ bytes_per_point × points + bytes_per_cell × occupied_cells(depth)
// (constants measured in bench/results/scale11.md; the ~105 MiB every fmv3d process has is not counted). Going one
// depth coarser divides the occupied cells of a surface by ~4, so lowering the depth is the stage's lever; the
// point term is not reduced (the cloud is the dense stage's output, bounded there).
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <functional>
#include <vector>

namespace fmv3d::surface {

// Fitted on two fused clouds at depths 7, 8, 9 (bench/results/mem12.md): 653k points (400-frame town orbit;
// 16k, 61k, 188k occupied cells; 177, 225, 358 MiB above the process's base) and 1.04M points (2,000-frame town
// grid; 16k, 66k, 274k cells; 281, 361, 643 MiB). The cell cost differs between them (≈ 1,100 B vs 1,400–1,700 B
// per cell), so the constants are the smallest that stay at or above all six measurements (0–20% above them),
// not a least-squares fit: the estimate is a bound.
struct PoissonMemoryModel {
  double bytes_per_point = 300;  // cloud + Open3D copy + k-d tree + solver samples
  double bytes_per_cell = 1350;  // octree nodes and their solver data per occupied finest cell
};

// Cells of the depth-`depth` grid over Open3D's reconstruction cube (1.1 × the largest extent of `bounds`,
// centred on it) that hold at least one point.
size_t OccupiedCells(const std::vector<Eigen::Vector3d>& points, const Eigen::AlignedBox3d& bounds, int depth);

// The model's bytes for `points` points and `cells` occupied cells.
double EstimatePoissonBytes(size_t points, size_t cells, const PoissonMemoryModel& model);

struct PoissonDepthChoice {
  int depth = 0;
  bool lowered = false;      // the budget made it coarser than wanted
  bool over_budget = false;  // even min_depth's estimate exceeds the budget (the point term alone may)
  double estimated_mb = 0;   // at the chosen depth
  size_t occupied_cells = 0;
};

// The finest depth from `wanted` down to `min_depth` whose estimate fits `budget_mb`; `cells_at(depth)` counts the
// occupied cells (OccupiedCells). At min_depth when none fits (over_budget). budget_mb <= 0: `wanted`, unchecked.
PoissonDepthChoice ChoosePoissonDepth(int wanted, int min_depth, size_t points, double budget_mb,
                                      const std::function<size_t(int)>& cells_at, const PoissonMemoryModel& model);

}  // namespace fmv3d::surface
