// Memory of the mesh stage, and the Poisson depth that keeps it within `--max-memory`.
//
// The stage's peak is the point arrays (the cloud as read, Open3D's copy with double normals and colours, the
// k-d tree, the solver's samples) plus Kazhdan's octree, whose nodes are refined around the samples: the finest
// level has about one node per octree cell that holds a point, and the coarser levels and the B-spline support
// around each add a constant factor. So the model is linear in the points and in the occupied cells at the
// depth:   bytes ≈ bytes_per_point × points + bytes_per_cell × occupied_cells(depth)
// (constants measured in bench/results/scale11.md; the ~105 MiB every fmv3d process has is not counted). Going one
// depth coarser divides the occupied cells of a surface by ~4.
//
// A cloud far denser than the wanted depth's cells (millions of fused points) can exhaust the budget with its point
// term alone, which no depth lowers. Before giving up depth, the points are averaged in the cells of a finer grid
// (a quarter or half of a Poisson cell, the finest that fits), so only the cloud as read and a k-d tree for the
// spacing are paid per input point:
//   bytes ≈ cloud_bytes + max(bytes_per_point_spacing × points,
//                             bytes_per_working_point × averaged points + bytes_per_cell × occupied_cells(depth))
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "fmv3d/io/point_cloud.h"

namespace fmv3d::surface {

// Fitted on two fused clouds at depths 7, 8, 9 (bench/results/mem12.md): 653k points (400-frame town orbit;
// 16k, 61k, 188k occupied cells; 177, 225, 358 MiB above the process's base) and 1.04M points (2,000-frame town
// grid; 16k, 66k, 274k cells; 281, 361, 643 MiB). The cell cost differs between them (≈ 1,100 B vs 1,400–1,700 B
// per cell), so the constants are the smallest that stay at or above all six measurements (0–20% above them),
// not a least-squares fit: the estimate is a bound.
struct PoissonMemoryModel {
  double bytes_per_point = 300;  // cloud + Open3D copy + k-d tree + solver samples
  double bytes_per_cell = 1350;  // octree nodes and their solver data per occupied finest cell
  // Averaged clouds (bench/results/edge22.md): the cloud as read is counted by its own bytes; what remains of the
  // 300 per point is Open3D's copy, the tree and the solver's samples, and the spacing's tree over every input
  // point (positions and a nanoflann index) comes and goes before them.
  double bytes_per_working_point = 200;
  double bytes_per_point_spacing = 90;
};

// Cell index of `p` in the depth-`depth` grid over Open3D's reconstruction cube (1.1 × the largest extent of
// `bounds`, centred on it), packed as 21 bits per axis; points outside are clamped to the border cells.
struct CellGrid {
  CellGrid(const Eigen::AlignedBox3d& bounds, int depth);
  uint64_t Key(const Eigen::Vector3d& p) const;
  Eigen::Vector3d origin;
  double cell = 1;
  int64_t cells_per_axis = 1;
};

// Cells of the depth-`depth` grid (CellGrid) that hold at least one point.
size_t OccupiedCells(const std::vector<Eigen::Vector3d>& points, const Eigen::AlignedBox3d& bounds, int depth);

// Heap and array bytes the cloud holds (its attribute arrays and every visibility list).
double ResidentBytes(const io::OrientedPointCloud& cloud);

// The model's bytes for `points` points and `cells` occupied cells.
double EstimatePoissonBytes(size_t points, size_t cells, const PoissonMemoryModel& model);
// The same for `points` input points (holding `cloud_bytes`) averaged to `averaged` points.
double EstimateAveragedPoissonBytes(size_t points, double cloud_bytes, size_t averaged, size_t cells,
                                    const PoissonMemoryModel& model);

struct PoissonDepthChoice {
  int depth = 0;
  bool lowered = false;      // the budget made it coarser than wanted
  bool over_budget = false;  // even min_depth's estimate exceeds the budget (the point term alone may)
  double estimated_mb = 0;   // at the chosen depth
  size_t occupied_cells = 0;
  // > 0: the points are averaged in the cells of this depth (depth + 2 or + 1) first, leaving `averaged_points`.
  int average_depth = 0;
  size_t averaged_points = 0;
};

// The finest depth from `wanted` down to `min_depth` whose estimate fits `budget_mb`, with every point or, when
// that does not fit, with the points averaged in quarter or half cells; `cells_at(depth)` counts the occupied cells
// (OccupiedCells). At min_depth, averaged when that helps, when none fits (over_budget). budget_mb <= 0:
// `wanted`, unchecked.
PoissonDepthChoice ChoosePoissonDepth(int wanted, int min_depth, size_t points, double cloud_bytes, double budget_mb,
                                      const std::function<size_t(int)>& cells_at, const PoissonMemoryModel& model);

// One point per occupied cell of the depth-`depth` grid over `bounds` (CellGrid), from the points `indices` of
// `cloud`: the mean position, the mean normal normalised (the first point's where they cancel), the mean colour
// (0..1, empty when the cloud has none).
struct CellAverages {
  std::vector<Eigen::Vector3d> points, normals, colors;
};
CellAverages AverageInCells(const io::OrientedPointCloud& cloud, const std::vector<size_t>& indices,
                            const Eigen::AlignedBox3d& bounds, int depth);

}  // namespace fmv3d::surface
