#include "fmv3d/surface/poisson_budget.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

namespace fmv3d::surface {

CellGrid::CellGrid(const Eigen::AlignedBox3d& bounds, int depth) {
  cells_per_axis = int64_t{1} << std::clamp(depth, 0, 20);
  const double cube = bounds.isEmpty() ? 0 : 1.1 * bounds.sizes().maxCoeff();
  cell = cube > 0 ? cube / static_cast<double>(cells_per_axis) : 1;
  origin = bounds.isEmpty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(bounds.center().array() - cube / 2);
  if (!(cube > 0)) cells_per_axis = 1;  // a single point or coincident points: one cell
}

uint64_t CellGrid::Key(const Eigen::Vector3d& p) const {
  uint64_t key = 0;
  for (int a = 0; a < 3; ++a) {
    const double c = std::floor((p[a] - origin[a]) / cell);
    const int64_t i = std::isfinite(c) ? static_cast<int64_t>(std::clamp(c, 0.0, double(cells_per_axis - 1))) : 0;
    key = (key << 21) | static_cast<uint64_t>(i);
  }
  return key;
}

size_t OccupiedCells(const std::vector<Eigen::Vector3d>& points, const Eigen::AlignedBox3d& bounds, int depth) {
  if (points.empty() || bounds.isEmpty()) return 0;
  const CellGrid grid(bounds, depth);
  // Sorted keys (8 B per point) rather than a hash set: a few million points stay a few tens of MB.
  std::vector<uint64_t> keys(points.size());
  for (size_t i = 0; i < points.size(); ++i) keys[i] = grid.Key(points[i]);
  std::sort(keys.begin(), keys.end());
  return static_cast<size_t>(std::unique(keys.begin(), keys.end()) - keys.begin());
}

double ResidentBytes(const io::OrientedPointCloud& cloud) {
  double bytes = static_cast<double>(
      cloud.positions.capacity() * sizeof(Eigen::Vector3d) + cloud.normals.capacity() * sizeof(Eigen::Vector3f) +
      cloud.colors.capacity() * sizeof(io::Rgb8) + cloud.sigma.capacity() * sizeof(float) +
      cloud.visibility.capacity() * sizeof(std::vector<uint32_t>));
  for (const auto& v : cloud.visibility)  // glibc's chunk: payload + 8, rounded up to 16, at least 32
    if (v.capacity() > 0) bytes += static_cast<double>(std::max<size_t>(32, (v.capacity() * 4 + 8 + 15) & ~size_t{15}));
  return bytes;
}

double EstimatePoissonBytes(size_t points, size_t cells, const PoissonMemoryModel& model) {
  return model.bytes_per_point * static_cast<double>(points) + model.bytes_per_cell * static_cast<double>(cells);
}

double EstimateAveragedPoissonBytes(size_t points, double cloud_bytes, size_t averaged, size_t cells,
                                    const PoissonMemoryModel& model) {
  return cloud_bytes + std::max(model.bytes_per_point_spacing * static_cast<double>(points),
                                model.bytes_per_working_point * static_cast<double>(averaged) +
                                    model.bytes_per_cell * static_cast<double>(cells));
}

PoissonDepthChoice ChoosePoissonDepth(int wanted, int min_depth, size_t points, double cloud_bytes, double budget_mb,
                                      const std::function<size_t(int)>& cells_at, const PoissonMemoryModel& model) {
  constexpr int kFinestAveraging = 2;  // quarter cells: up to 16 samples per cell across a surface
  std::map<int, size_t> counted;
  auto cells = [&](int depth) {
    auto it = counted.find(depth);
    if (it == counted.end()) it = counted.emplace(depth, cells_at(depth)).first;
    return it->second;
  };
  constexpr double kMiB = 1048576.0;
  PoissonDepthChoice choice;
  for (int depth = wanted;; --depth) {
    choice = PoissonDepthChoice{};
    choice.depth = depth;
    choice.occupied_cells = cells(depth);
    choice.estimated_mb = EstimatePoissonBytes(points, choice.occupied_cells, model) / kMiB;
    if (budget_mb <= 0 || choice.estimated_mb <= budget_mb) break;
    // The finest averaging grid that fits: the solver weighs every sample alike, so an averaged point stands for
    // as much surface as a lone stray one; finer grids keep more of the cloud's density.
    bool fits = false;
    for (int average = depth + kFinestAveraging; average > depth && !fits; --average) {
      const size_t averaged = cells(average);
      if (averaged >= points) continue;
      const double averaged_mb =
          EstimateAveragedPoissonBytes(points, cloud_bytes, averaged, choice.occupied_cells, model) / kMiB;
      fits = averaged_mb <= budget_mb;
      if (fits || averaged_mb < choice.estimated_mb) {
        choice.estimated_mb = averaged_mb;
        choice.average_depth = average;
        choice.averaged_points = averaged;
      }
    }
    if (fits) break;
    if (depth <= min_depth) {
      choice.over_budget = true;
      break;
    }
  }
  choice.lowered = choice.depth < wanted;
  return choice;
}

CellAverages AverageInCells(const io::OrientedPointCloud& cloud, const std::vector<size_t>& indices,
                            const Eigen::AlignedBox3d& bounds, int depth) {
  CellAverages out;
  if (indices.empty()) return out;
  const CellGrid grid(bounds, depth);
  std::vector<std::pair<uint64_t, uint32_t>> keyed(indices.size());  // (cell, position in `indices`)
  for (size_t i = 0; i < indices.size(); ++i)
    keyed[i] = {grid.Key(cloud.positions[indices[i]]), static_cast<uint32_t>(i)};
  std::sort(keyed.begin(), keyed.end());
  const bool normals = cloud.has_normals(), colors = cloud.has_colors();
  for (size_t begin = 0; begin < keyed.size();) {
    size_t end = begin;
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero(), c = Eigen::Vector3d::Zero();
    for (; end < keyed.size() && keyed[end].first == keyed[begin].first; ++end) {
      const size_t k = indices[keyed[end].second];
      p += cloud.positions[k];
      if (normals) n += cloud.normals[k].cast<double>();
      if (colors) c += cloud.colors[k].cast<double>();
    }
    const double count = static_cast<double>(end - begin);
    out.points.push_back(p / count);
    if (normals) {
      // Opposite faces of a sheet thinner than the cell cancel: keep one side rather than a zero normal.
      const double norm = n.norm();
      out.normals.push_back(norm > 1e-6 * count ? Eigen::Vector3d(n / norm)
                                                : cloud.normals[indices[keyed[begin].second]].cast<double>());
    }
    if (colors) out.colors.push_back(c / (255.0 * count));
    begin = end;
  }
  return out;
}

}  // namespace fmv3d::surface
