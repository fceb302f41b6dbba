#include "fmv3d/surface/poisson.h"

#include <open3d/geometry/BoundingVolume.h>
#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/geometry/TriangleMesh.h>
#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <string>

#include "fmv3d/core/error.h"
#include "fmv3d/core/threading.h"

namespace fmv3d::surface {
namespace {

using O3dMesh = open3d::geometry::TriangleMesh;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

// Nearest input point of every query (index), in parallel; the tree is only read.
std::vector<int> NearestPoints(const open3d::geometry::KDTreeFlann& tree, const std::vector<Eigen::Vector3d>& queries,
                               std::vector<double>* distances) {
  std::vector<int> nearest(queries.size(), -1);
  if (distances) distances->assign(queries.size(), std::numeric_limits<double>::infinity());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, queries.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> idx;
    std::vector<double> d2;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      if (tree.SearchKNN(queries[i], 1, idx, d2) > 0) {
        nearest[i] = idx[0];
        if (distances) (*distances)[i] = std::sqrt(d2[0]);
      }
    }
  });
  return nearest;
}

std::string DescribeCounts(const O3dMesh& m) {
  return std::to_string(m.vertices_.size()) + " vertices, " + std::to_string(m.triangles_.size()) + " faces";
}

}  // namespace

void PoissonOptions::Check() const {
  if (depth < 0 || depth > 14) throw Error("poisson: depth must be 0 (automatic) or 1..14");
  if (!(cell_to_spacing > 0)) throw Error("poisson: cell_to_spacing must be positive");
  if (min_depth < 1 || max_depth > 14 || min_depth > max_depth)
    throw Error("poisson: need 1 <= min_depth <= max_depth <= 14");
  if (!(density_quantile >= 0 && density_quantile <= 0.9)) throw Error("poisson: density quantile must be in [0, 0.9]");
  if (!(max_point_distance >= 0)) throw Error("poisson: max_point_distance must be >= 0");
  components.Check();
  if (!(crop_margin >= 0)) throw Error("poisson: crop margin must be >= 0");
  if (target_faces < 0) throw Error("poisson: target face count must be >= 0");
  if (threads < 0) throw Error("poisson: threads must be >= 0");
  if (!(memory.bytes_per_point >= 0 && memory.bytes_per_cell >= 0 && memory.bytes_per_working_point >= 0 &&
        memory.bytes_per_point_spacing >= 0))
    throw Error("poisson: memory model bytes must be >= 0");
}

namespace {

double SpacingFromTree(const open3d::geometry::KDTreeFlann& tree, const std::vector<Eigen::Vector3d>& points,
                       size_t max_queries) {
  constexpr int kK = 7;  // the query point itself + 6 neighbours
  if (points.size() < static_cast<size_t>(kK)) return 0;
  const size_t n = std::min(points.size(), std::max<size_t>(max_queries, 1));
  const double step = static_cast<double>(points.size()) / n;
  std::vector<double> spacing(n, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 512), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> idx;
    std::vector<double> d2;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const size_t p = static_cast<size_t>(i * step);
      if (tree.SearchKNN(points[p], kK, idx, d2) == kK)
        // A surface with density ρ holds 6 points within r6: π r6² ρ = 6, spacing = 1/√ρ = r6 √(π/6).
        spacing[i] = std::sqrt(d2[kK - 1]) * std::sqrt(M_PI / 6.0);
    }
  });
  auto mid = spacing.begin() + spacing.size() / 2;
  std::nth_element(spacing.begin(), mid, spacing.end());
  return *mid;
}

// Spacing around each query point (as SpacingFromTree, per point).
std::vector<double> LocalSpacings(const open3d::geometry::KDTreeFlann& tree,
                                  const std::vector<Eigen::Vector3d>& queries) {
  constexpr int kK = 7;
  std::vector<double> out(queries.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, queries.size(), 2048), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> idx;
    std::vector<double> d2;
    for (size_t i = r.begin(); i < r.end(); ++i)
      if (tree.SearchKNN(queries[i], kK, idx, d2) == kK) out[i] = std::sqrt(d2[kK - 1]) * std::sqrt(M_PI / 6.0);
  });
  return out;
}

// Per-axis [q, 1 − q] quantiles of the points: the extent of the scene without its stray far points.
Eigen::AlignedBox3d RobustBounds(const std::vector<Eigen::Vector3d>& points, double q) {
  Eigen::AlignedBox3d box;
  if (points.empty()) return box;
  std::vector<double> c(points.size());
  for (int axis = 0; axis < 3; ++axis) {
    for (size_t i = 0; i < points.size(); ++i) c[i] = points[i][axis];
    const size_t lo = static_cast<size_t>(q * (c.size() - 1)), hi = c.size() - 1 - lo;
    std::nth_element(c.begin(), c.begin() + lo, c.end());
    box.min()[axis] = c[lo];
    std::nth_element(c.begin(), c.begin() + hi, c.end());
    box.max()[axis] = c[hi];
  }
  return box;
}

}  // namespace

double MedianPointSpacing(const std::vector<Eigen::Vector3d>& points, size_t max_queries) {
  if (points.size() < 7) return 0;
  open3d::geometry::PointCloud pc;
  pc.points_ = points;
  const open3d::geometry::KDTreeFlann tree(pc);
  return SpacingFromTree(tree, points, max_queries);
}

int AutomaticDepth(const Eigen::AlignedBox3d& bounds, double spacing, const PoissonOptions& options) {
  if (!(spacing > 0) || bounds.isEmpty()) return options.min_depth;
  const double cube = 1.1 * bounds.sizes().maxCoeff();  // Open3D's default scale
  // Nearest depth in log scale: the cell is within a factor √2 of the wanted width (rounding up would make
  // it up to 2× finer, 8× the octree nodes and time, for no accuracy: finer cells fit the noise).
  const int depth = static_cast<int>(std::lround(std::log2(cube / (options.cell_to_spacing * spacing))));
  return std::clamp(depth, options.min_depth, options.max_depth);
}

namespace {

// Stray points far from the scene would blow up Poisson's cube (and so coarsen every cell): the working box is
// the 0.1–99.9% quantile box of the points, enlarged by the crop margin; points outside are dropped. The indices
// of the points kept.
std::vector<size_t> PointsInWorkingBox(const io::OrientedPointCloud& cloud, const PoissonOptions& options,
                                       Eigen::AlignedBox3d* working_box, nlohmann::json* st) {
  Eigen::AlignedBox3d& bounds = *working_box;
  bounds = RobustBounds(cloud.positions, 0.001);
  {
    const double margin = options.crop_margin * bounds.diagonal().norm();
    bounds.min().array() -= margin;
    bounds.max().array() += margin;
  }
  std::vector<size_t> kept;
  kept.reserve(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i)
    if (bounds.contains(cloud.positions[i])) kept.push_back(i);
  (*st)["points_outside_bounds"] = cloud.size() - kept.size();
  if (kept.size() < 16) throw Error("poisson: too few points (" + std::to_string(kept.size()) + ") for a surface");
  return kept;
}

// The solver's cloud: the kept points as they are (`pc` already holds their positions) ...
void AddNormalsAndColours(const io::OrientedPointCloud& cloud, const std::vector<size_t>& kept,
                          open3d::geometry::PointCloud* pc) {
  pc->normals_.reserve(kept.size());
  for (size_t i : kept) pc->normals_.push_back(cloud.normals[i].cast<double>());
  if (cloud.has_colors()) {
    pc->colors_.reserve(kept.size());
    for (size_t i : kept) pc->colors_.push_back(cloud.colors[i].cast<double>() / 255.0);
  }
}

// ... or averaged in the cells of `average_depth` (poisson_budget.h) when every point does not fit the budget.
open3d::geometry::PointCloud AveragedCloud(const io::OrientedPointCloud& cloud, const std::vector<size_t>& kept,
                                           const Eigen::AlignedBox3d& box, int average_depth) {
  CellAverages a = AverageInCells(cloud, kept, box, average_depth);
  open3d::geometry::PointCloud pc;
  pc.points_ = std::move(a.points);
  pc.normals_ = std::move(a.normals);
  pc.colors_ = std::move(a.colors);
  return pc;
}

// Open surfaces: trim by density and by distance to the samples, in one vertex mask.
void TrimOpenSurface(const open3d::geometry::KDTreeFlann& tree, const open3d::geometry::PointCloud& pc,
                     const std::vector<double>& densities, double spacing, double cell, const PoissonOptions& options,
                     O3dMesh* mesh_out, nlohmann::json* stats) {
  O3dMesh& mesh = *mesh_out;
  nlohmann::json& st = *stats;
  std::vector<double> dist;
  const std::vector<int> nearest = NearestPoints(tree, mesh.vertices_, &dist);
  std::vector<bool> remove(mesh.vertices_.size(), false);
  size_t density_trimmed = 0, distance_trimmed = 0;
  if (options.density_quantile > 0 && densities.size() == mesh.vertices_.size()) {
    std::vector<double> sorted = densities;
    const size_t k = std::min(sorted.size() - 1, static_cast<size_t>(options.density_quantile * sorted.size()));
    std::nth_element(sorted.begin(), sorted.begin() + k, sorted.end());
    const double threshold = sorted[k];
    st["density_threshold"] = threshold;
    for (size_t i = 0; i < densities.size(); ++i)
      if (densities[i] < threshold && dist[i] > cell) remove[i] = true, ++density_trimmed;
  }
  if (options.max_point_distance > 0 && spacing > 0) {
    // The local spacing of each vertex's nearest point (computed once per point that is someone's nearest):
    // a sparsely sampled surface (far land) keeps its mesh; the limit never goes below one cell (Poisson
    // vertices sit on the cell grid) nor below the median spacing.
    std::vector<int> unique = nearest;
    std::sort(unique.begin(), unique.end());
    unique.erase(std::unique(unique.begin(), unique.end()), unique.end());
    if (!unique.empty() && unique.front() < 0) unique.erase(unique.begin());
    std::vector<Eigen::Vector3d> queries(unique.size());
    for (size_t i = 0; i < unique.size(); ++i) queries[i] = pc.points_[unique[i]];
    const std::vector<double> local = LocalSpacings(tree, queries);
    std::vector<double> local_of(pc.points_.size(), 0);
    for (size_t i = 0; i < unique.size(); ++i) local_of[unique[i]] = local[i];
    for (size_t i = 0; i < dist.size(); ++i) {
      if (remove[i] || nearest[i] < 0) continue;
      // A point at the edge of an evenly sampled surface has a local spacing up to ~1.5x the median (its
      // neighbours are on one side): only a surface sampled clearly sparser gets its own spacing.
      const double local_spacing = local_of[nearest[i]] > 2 * spacing ? local_of[nearest[i]] : spacing;
      const double limit = options.max_point_distance * local_spacing;
      if (dist[i] > std::max(limit, cell)) remove[i] = true, ++distance_trimmed;
    }
  }
  mesh.RemoveVerticesByMask(remove);
  st["trimmed"] = {{"vertices", mesh.vertices_.size()},
                   {"faces", mesh.triangles_.size()},
                   {"by_density", density_trimmed},
                   {"by_distance", distance_trimmed}};
  if (mesh.triangles_.empty()) throw Error("poisson: nothing left after trimming low-density vertices");
}

// Every piece the points support.
void KeepSupportedPieces(const open3d::geometry::PointCloud& pc, double spacing, double cell,
                         const PoissonOptions& options, O3dMesh* mesh_out, nlohmann::json* stats) {
  O3dMesh& mesh = *mesh_out;
  nlohmann::json& st = *stats;
  const ComponentSelection sel =
      SelectComponents(mesh.vertices_, mesh.triangles_, pc.points_, cell, spacing, options.components);
  std::vector<bool> drop(mesh.triangles_.size(), false);
  for (size_t i = 0; i < drop.size(); ++i)
    drop[i] = sel.components[sel.face_component[i]].decision != ComponentDecision::kKept;
  mesh.RemoveTrianglesByMask(drop);
  mesh.RemoveUnreferencedVertices();
  nlohmann::json dropped = nlohmann::json::object();
  double kept_area = 0, dropped_area = 0;
  for (const auto& c : sel.components) {
    if (c.decision == ComponentDecision::kKept) {
      kept_area += c.area;
    } else {
      dropped_area += c.area;
      auto& d = dropped[ToString(c.decision)];
      d = d.is_null() ? 1 : d.get<int>() + 1;
    }
  }
  st["components"] = {{"found", sel.components.size()},
                      {"kept", sel.kept()},
                      {"kept_area", kept_area},
                      {"dropped_area", dropped_area},
                      {"dropped", dropped}};
  spdlog::info("poisson: {} of {} connected pieces kept ({:.1f}% of their area)", sel.kept(), sel.components.size(),
               100 * kept_area / std::max(kept_area + dropped_area, 1e-300));
}

io::Rgb8 ToRgb8(const Eigen::Vector3d& c) {
  io::Rgb8 rgb;
  for (int k = 0; k < 3; ++k) rgb[k] = static_cast<uint8_t>(std::clamp(std::lround(c[k] * 255.0), 0L, 255L));
  return rgb;
}

// Open3D's mesh as ours, its triangles wound the way the input normals face (renderer back-face culling and the
// signed distances of the comparison rely on it), with the points' colours.
ColoredMesh ToColoredMesh(const O3dMesh& mesh, const open3d::geometry::KDTreeFlann& tree,
                          const open3d::geometry::PointCloud& pc) {
  ColoredMesh out;
  out.vertices = mesh.vertices_;
  out.triangles = mesh.triangles_;
  // Vote over the faces with their nearest point's normal.
  std::vector<Eigen::Vector3d> centroids(out.triangles.size());
  for (size_t i = 0; i < out.triangles.size(); ++i) {
    const auto& f = out.triangles[i];
    centroids[i] = (out.vertices[f[0]] + out.vertices[f[1]] + out.vertices[f[2]]) / 3.0;
  }
  const std::vector<int> nearest_face_point = NearestPoints(tree, centroids, nullptr);
  double vote = 0;
  for (size_t i = 0; i < out.triangles.size(); ++i) {
    const auto& f = out.triangles[i];
    const Eigen::Vector3d n = (out.vertices[f[1]] - out.vertices[f[0]]).cross(out.vertices[f[2]] - out.vertices[f[0]]);
    if (nearest_face_point[i] >= 0) vote += n.dot(pc.normals_[nearest_face_point[i]]) > 0 ? 1 : -1;
  }
  if (vote < 0)
    for (auto& f : out.triangles) std::swap(f[1], f[2]);
  out.ComputeVertexNormals();

  if (pc.HasColors()) {
    if (mesh.vertex_colors_.size() == mesh.vertices_.size()) {
      out.colors.reserve(mesh.vertices_.size());
      for (const auto& c : mesh.vertex_colors_) out.colors.push_back(ToRgb8(c));
    } else {  // decimation may drop the interpolated colours: take the nearest point's
      const std::vector<int> nearest = NearestPoints(tree, out.vertices, nullptr);
      out.colors.reserve(out.vertices.size());
      for (int p : nearest) out.colors.push_back(p >= 0 ? ToRgb8(pc.colors_[p]) : io::Rgb8(128, 128, 128));
    }
  }
  return out;
}

// The wanted depth, lowered (and the points averaged first) while the memory model exceeds the budget
// (poisson_budget.h); st["memory"] says so.
PoissonDepthChoice DepthWithinBudget(int wanted, const io::OrientedPointCloud& cloud, size_t points,
                                     const open3d::geometry::PointCloud& pc, const Eigen::AlignedBox3d& box,
                                     const PoissonOptions& options, nlohmann::json* st) {
  const double cloud_bytes = ResidentBytes(cloud);
  const PoissonDepthChoice c = ChoosePoissonDepth(
      wanted, std::min(wanted, options.min_depth), points, cloud_bytes, options.max_memory_mb,
      [&](int d) { return OccupiedCells(pc.points_, box, d); }, options.memory);
  (*st)["memory"] = {{"max_memory_mb", options.max_memory_mb},
                     {"depth_wanted", wanted},
                     {"depth", c.depth},
                     {"lowered_by_budget", c.lowered},
                     {"over_budget", c.over_budget},
                     {"estimated_mb", c.estimated_mb},
                     {"occupied_cells", c.occupied_cells},
                     {"cloud_mb", cloud_bytes / 1048576.0},
                     {"averaged_in_depth", c.average_depth},
                     {"averaged_points", c.averaged_points},
                     {"bytes_per_point", options.memory.bytes_per_point},
                     {"bytes_per_cell", options.memory.bytes_per_cell},
                     {"bytes_per_working_point", options.memory.bytes_per_working_point},
                     {"bytes_per_point_spacing", options.memory.bytes_per_point_spacing}};
  if (c.average_depth > 0)
    spdlog::info("poisson: {} points averaged to {} in the cells of depth {} for --max-memory {} MB", points,
                 c.averaged_points, c.average_depth, options.max_memory_mb);
  if (c.lowered)
    spdlog::warn("poisson: octree depth {} → {} to fit --max-memory {} MB (estimate {:.0f} MB)", wanted, c.depth,
                 options.max_memory_mb, c.estimated_mb);
  if (c.over_budget)
    spdlog::warn("poisson: {} points at depth {} need an estimated {:.0f} MB, over --max-memory {} MB", points, c.depth,
                 c.estimated_mb, options.max_memory_mb);
  return c;
}

Eigen::AlignedBox3d BoxOf(const std::vector<Eigen::Vector3d>& points) {
  Eigen::AlignedBox3d box;
  for (const auto& p : points) box.extend(p);
  return box;
}

}  // namespace

ColoredMesh ReconstructPoisson(const io::OrientedPointCloud& cloud, const PoissonOptions& options,
                               nlohmann::json* stats) {
  options.Check();
  cloud.Validate();
  if (cloud.empty()) throw Error("poisson: the point cloud is empty");
  if (!cloud.has_normals()) throw Error("poisson: the point cloud has no normals");
  if (cloud.size() < 16) throw Error("poisson: too few points (" + std::to_string(cloud.size()) + ") for a surface");
  nlohmann::json st;
  const auto start = Clock::now();

  Eigen::AlignedBox3d bounds;
  const std::vector<size_t> kept = PointsInWorkingBox(cloud, options, &bounds, &st);
  open3d::geometry::PointCloud pc;
  pc.points_.reserve(kept.size());
  for (size_t i : kept) pc.points_.push_back(cloud.positions[i]);
  auto tree = std::make_unique<open3d::geometry::KDTreeFlann>(pc);
  const double spacing = SpacingFromTree(*tree, pc.points_, 20000);
  Eigen::AlignedBox3d kept_box = BoxOf(pc.points_);  // Open3D's cube is 1.1 × the largest extent of its points
  const int wanted = options.depth > 0 ? options.depth : AutomaticDepth(kept_box, spacing, options);
  const PoissonDepthChoice choice = DepthWithinBudget(wanted, cloud, kept.size(), pc, kept_box, options, &st);
  const int depth = choice.depth;
  double working_spacing = spacing;  // of the points the solver gets, which trimming measures against
  if (choice.average_depth > 0) {
    tree.reset();
    pc = AveragedCloud(cloud, kept, kept_box, choice.average_depth);
    tree = std::make_unique<open3d::geometry::KDTreeFlann>(pc);
    working_spacing = SpacingFromTree(*tree, pc.points_, 20000);
    kept_box = BoxOf(pc.points_);
  } else {
    AddNormalsAndColours(cloud, kept, &pc);
  }
  st["points"] = cloud.size();
  st["solver_points"] = pc.points_.size();
  st["point_spacing"] = spacing;
  st["solver_point_spacing"] = working_spacing;
  st["depth"] = depth;
  st["cell_width"] = 1.1 * kept_box.sizes().maxCoeff() / std::ldexp(1.0, depth);
  spdlog::info("poisson: {} points ({} to the solver), spacing {:.4g}, octree depth {} (cell {:.4g})", cloud.size(),
               pc.points_.size(), spacing, depth, st["cell_width"].get<double>());

  auto t = Clock::now();
  int threads = options.threads;
  if (threads == 0) {
    const char* wait = std::getenv("OMP_WAIT_POLICY");
    threads = wait && (std::string(wait) == "passive" || std::string(wait) == "PASSIVE") ? core::NumThreads() : 1;
  }
  st["threads"] = threads;
  auto [mesh_ptr, densities] =
      O3dMesh::CreateFromPointCloudPoisson(pc, static_cast<size_t>(depth), 0.0f, 1.1f, options.linear_fit, threads);
  if (!mesh_ptr || mesh_ptr->triangles_.empty()) throw Error("poisson: the reconstruction produced no surface");
  O3dMesh& mesh = *mesh_ptr;
  st["seconds_poisson"] = Seconds(t);
  st["raw"] = {{"vertices", mesh.vertices_.size()}, {"faces", mesh.triangles_.size()}};
  spdlog::debug("poisson: raw {}", DescribeCounts(mesh));

  t = Clock::now();
  // 2 + 3: trim by density and by distance to the samples, in one vertex mask (open surfaces only).
  const double cell = st["cell_width"].get<double>();
  st["kind"] = ToString(options.kind);
  if (options.kind == SurfaceKind::kOpen)
    TrimOpenSurface(*tree, pc, densities, working_spacing, cell, options, &mesh, &st);

  KeepSupportedPieces(pc, working_spacing, cell, options, &mesh, &st);

  // 5. Crop to the working box (the points' robust bounds, enlarged); a watertight surface stays closed.
  if (options.kind == SurfaceKind::kOpen) {
    const Eigen::Vector3d lo = bounds.min(), hi = bounds.max();
    std::vector<bool> outside(mesh.vertices_.size(), false);
    for (size_t i = 0; i < mesh.vertices_.size(); ++i)
      outside[i] = (mesh.vertices_[i].array() < lo.array()).any() || (mesh.vertices_[i].array() > hi.array()).any();
    mesh.RemoveVerticesByMask(outside);
  }
  st["cleaned"] = {{"vertices", mesh.vertices_.size()}, {"faces", mesh.triangles_.size()}};
  if (mesh.triangles_.empty()) throw Error("poisson: nothing left after cropping to the points' bounds");

  // 6. Decimation.
  if (options.target_faces > 0 && mesh.triangles_.size() > static_cast<size_t>(options.target_faces)) {
    auto simplified =
        mesh.SimplifyQuadricDecimation(options.target_faces, std::numeric_limits<double>::infinity(), 1.0);
    simplified->RemoveDegenerateTriangles();
    simplified->RemoveUnreferencedVertices();
    if (simplified->triangles_.empty()) throw Error("poisson: decimation left no faces");
    mesh = *simplified;
    st["decimated"] = {{"vertices", mesh.vertices_.size()}, {"faces", mesh.triangles_.size()}};
  }
  st["seconds_cleanup"] = Seconds(t);

  ColoredMesh out = ToColoredMesh(mesh, *tree, pc);
  st["vertices"] = out.vertices.size();
  st["faces"] = out.triangles.size();
  st["area"] = out.SurfaceArea();
  st["seconds"] = Seconds(start);
  spdlog::info("poisson: {} vertices, {} faces after clean-up ({:.1f} s)", out.vertices.size(), out.triangles.size(),
               st["seconds"].get<double>());
  if (stats) *stats = std::move(st);
  return out;
}

}  // namespace fmv3d::surface
