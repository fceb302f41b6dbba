// Surface from oriented points: screened Poisson reconstruction (Kazhdan & Hoppe 2013, Open3D's binding of
// Kazhdan's PoissonRecon) followed by the clean-up that makes its watertight output a faithful surface:
//   1. octree depth from the point density: the finest cell is about `cell_to_spacing` × the median point
//      spacing (finer cells only fit the noise; coarser ones round edges off);
//   2. trim (open surfaces only): Poisson closes every hole with a smooth membrane far from the samples; those
//      vertices have a low sample density (the value Open3D returns per vertex), so the lowest
//      `density_quantile` of them go, unless a point lies within one cell (mesh_cleanup.h);
//   3. trim the membrane further by distance (open surfaces only): vertices farther than
//      `max_point_distance` × the local point spacing (that of their nearest point, at least the median
//      spacing and one cell) from every input point are removed (0 disables);
//   4. keep every connected piece that the points support (mesh_cleanup.h: support, area, support density),
//      dropping floating blobs fitted to outliers whatever the size of the largest piece;
//   5. crop to the points' bounding box enlarged by `crop_margin` × its diagonal (the box of the 0.1–99.9%
//      quantiles per axis: stray far points are dropped before reconstruction, as they would otherwise
//      inflate Poisson's cube and coarsen every cell);
//   6. optional quadric decimation to `target_faces`.
// When the memory model of poisson_budget.h exceeds `max_memory_mb` at the depth of step 1 (or the one asked for),
// the points are averaged in quarter or half cells, and the depth is lowered only while that does not fit either.
// Vertex colours are interpolated from the points' colours; triangles are wound so that their normals agree
// with the input normals (towards the cameras).
#pragma once

#include <nlohmann/json.hpp>

#include "fmv3d/io/point_cloud.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fmv3d/surface/mesh_cleanup.h"
#include "fmv3d/surface/poisson_budget.h"

namespace fmv3d::surface {

struct PoissonOptions {
  int depth = 0;                 // octree depth; 0 = from the point density
  double cell_to_spacing = 2.0;  // automatic depth: finest cell width / median point spacing
  int min_depth = 6, max_depth = 12;
  bool linear_fit = true;                 // iso-vertices placed by linear interpolation (more accurate)
  double density_quantile = 0.02;         // share of the lowest-density vertices trimmed (0..0.9)
  double max_point_distance = 3.0;        // trim vertices farther than this × spacing from every point; 0 = off
  SurfaceKind kind = SurfaceKind::kOpen;  // kWatertight: no trimming (steps 2 and 3)
  ComponentOptions components;            // step 4
  double crop_margin = 0.02;              // bounding-box enlargement, fraction of its diagonal
  int target_faces = 0;                   // quadric decimation target; 0 = none
  // Threads of the Poisson solver; 0 = automatic: 1, or core::NumThreads() when OMP_WAIT_POLICY=passive.
  // Open3D's solver runs on OpenMP, whose waiting threads spin: on a loaded machine two threads ran 10–15×
  // slower than one (a 20k-point sphere: 5 s vs 50–77 s); with passive waiting they help.
  int threads = 0;
  // Memory budget of the reconstruction (poisson_budget.h): points averaged, then the depth lowered, until the
  // model's estimate fits (report: "memory"); <= 0 = no limit.
  double max_memory_mb = 2048;
  PoissonMemoryModel memory;
  // Throws fmv3d::Error naming the bad field.
  void Check() const;
};

// Median distance between neighbouring points of a surface sample (from the 6th-neighbour distance, which
// duplicates do not fool), estimated on at most `max_queries` evenly spread points. 0 for < 7 points.
double MedianPointSpacing(const std::vector<Eigen::Vector3d>& points, size_t max_queries = 20000);

// Depth whose finest cell is nearest (in log scale) to cell_to_spacing × spacing for Open3D's reconstruction cube (1.1
// × the largest extent of the points), clamped to [min_depth, max_depth].
int AutomaticDepth(const Eigen::AlignedBox3d& bounds, double spacing, const PoissonOptions& options);

// Requires normals. `stats` (optional) receives the spacing, depth and the vertex/face counts after each
// step. Throws fmv3d::Error when the cloud is empty, has no normals, or nothing survives the clean-up.
ColoredMesh ReconstructPoisson(const io::OrientedPointCloud& cloud, const PoissonOptions& options,
                               nlohmann::json* stats = nullptr);

}  // namespace fmv3d::surface
