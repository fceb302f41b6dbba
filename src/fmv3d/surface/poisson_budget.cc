#include "fmv3d/surface/poisson_budget.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_set>

namespace fmv3d::surface {

size_t OccupiedCells(const std::vector<Eigen::Vector3d>& points, const Eigen::AlignedBox3d& bounds, int depth) {
  if (points.empty() || bounds.isEmpty()) return 0;
  const double cube = 1.1 * bounds.sizes().maxCoeff();
  if (!(cube > 0)) return 1;
  const int64_t n = int64_t{1} << std::clamp(depth, 0, 20);
  const Eigen::Vector3d origin = bounds.center().array() - cube / 2;
  std::unordered_set<uint64_t> cells;
  cells.reserve(points.size() / 4);
  for (const auto& p : points) {
    uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      const auto c = static_cast<int64_t>(std::floor((p[a] - origin[a]) / cube * static_cast<double>(n)));
      key = (key << 21) | static_cast<uint64_t>(std::clamp<int64_t>(c, 0, n - 1));
    }
    cells.insert(key);
  }
  return cells.size();
}

double EstimatePoissonBytes(size_t points, size_t cells, const PoissonMemoryModel& model) {
  return model.bytes_per_point * static_cast<double>(points) + model.bytes_per_cell * static_cast<double>(cells);
}

PoissonDepthChoice ChoosePoissonDepth(int wanted, int min_depth, size_t points, double budget_mb,
                                      const std::function<size_t(int)>& cells_at, const PoissonMemoryModel& model) {
  PoissonDepthChoice choice;
  for (int depth = wanted;; --depth) {
    choice.depth = depth;
    choice.occupied_cells = cells_at(depth);
    choice.estimated_mb = EstimatePoissonBytes(points, choice.occupied_cells, model) / 1048576.0;
    if (budget_mb <= 0 || choice.estimated_mb <= budget_mb) break;
    if (depth <= min_depth) {
      choice.over_budget = true;
      break;
    }
  }
  choice.lowered = choice.depth < wanted;
  return choice;
}

}  // namespace fmv3d::surface
