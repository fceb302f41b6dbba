#include "fmv3d/pipeline/point_octree.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "fmv3d/core/error.h"

namespace fmv3d::pipeline {

void OctreeOptions::Check() const {
  if (max_points_per_tile < 64) throw Error("tiles: the per-tile point budget must be at least 64");
  if (max_depth < 0 || max_depth > 30) throw Error("tiles: the octree depth must be in [0, 30]");
}

namespace {

// Marks (in `selected`, one byte per point of the range) one point per occupied cell of a g³ grid over `cell`,
// with g chosen so that at most `budget` cells are occupied (g shrinks until they fit; a surface occupies
// ~g² cells, a volume ~g³). Returns the number marked.
size_t SelectUniform(const TilePoint* pts, size_t n, const Eigen::AlignedBox3f& cell, size_t budget,
                     std::vector<uint8_t>* selected) {
  double g = std::ceil(std::sqrt(static_cast<double>(budget)));
  const Eigen::Vector3f lo = cell.min();
  const float size = std::max(cell.sizes().maxCoeff(), 1e-9f);
  std::unordered_set<uint64_t> occupied;
  for (int attempt = 0;; ++attempt) {
    const int gi = std::max(1, static_cast<int>(g));
    const float inv = static_cast<float>(gi) / size;
    occupied.clear();
    occupied.reserve(std::min(n, budget * 2));
    selected->assign(n, 0);
    size_t count = 0;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3f q = (pts[i].position - lo) * inv;
      auto idx = [gi](float v) { return static_cast<uint64_t>(std::clamp(static_cast<int>(v), 0, gi - 1)); };
      const uint64_t key = (idx(q.x()) << 42) | (idx(q.y()) << 21) | idx(q.z());
      if (occupied.insert(key).second) {
        (*selected)[i] = 1;
        if (++count > budget) break;
      }
    }
    if (count <= budget) return count;
    if (gi == 1 || attempt >= 8) {
      // Still too many: keep an even stride of the marked points.
      selected->assign(n, 0);
      const size_t stride = (n + budget - 1) / budget;
      count = 0;
      for (size_t i = 0; i < n; i += stride) (*selected)[i] = 1, ++count;
      return count;
    }
    g *= 0.75;
  }
}

// Moves the marked points to the front of the range (points and marks swapped together).
void MoveSelectedToFront(TilePoint* pts, size_t n, std::vector<uint8_t>* selected) {
  size_t front = 0;
  for (size_t i = 0; i < n; ++i)
    if ((*selected)[i]) {
      std::swap(pts[front], pts[i]);
      std::swap((*selected)[front], (*selected)[i]);
      ++front;
    }
}

struct Builder {
  const OctreeOptions& o;
  std::vector<TilePoint>& pts;
  std::vector<OctreeNode>& nodes;
  std::vector<uint8_t> selected;

  int Build(size_t begin, size_t end, const Eigen::AlignedBox3f& cell, int level, const std::string& name) {
    const int id = static_cast<int>(nodes.size());
    nodes.emplace_back();
    {
      OctreeNode& node = nodes.back();
      node.begin = begin;
      node.subtree_end = end;
      node.cell = cell;
      node.level = level;
      node.name = name;
      for (size_t i = begin; i < end; ++i) node.bounds.extend(pts[i].position);
    }
    const size_t n = end - begin;
    if (n <= o.max_points_per_tile || level >= o.max_depth) {
      nodes[id].count = n;
      return id;
    }
    const size_t k = SelectUniform(pts.data() + begin, n, cell, o.max_points_per_tile, &selected);
    MoveSelectedToFront(pts.data() + begin, n, &selected);
    nodes[id].count = k;
    // The rest into octants: split on x, then each half on y, then each quarter on z.
    const Eigen::Vector3f c = cell.center();
    auto first = pts.begin() + static_cast<std::ptrdiff_t>(begin + k),
         last = pts.begin() + static_cast<std::ptrdiff_t>(end);
    auto mx = std::partition(first, last, [&](const TilePoint& p) { return p.position.x() < c.x(); });
    std::vector<decltype(first)> bounds = {first};
    for (auto [a, b] : {std::pair{first, mx}, std::pair{mx, last}}) {
      auto my = std::partition(a, b, [&](const TilePoint& p) { return p.position.y() < c.y(); });
      for (auto [u, v] : {std::pair{a, my}, std::pair{my, b}}) {
        auto mz = std::partition(u, v, [&](const TilePoint& p) { return p.position.z() < c.z(); });
        bounds.push_back(mz);
        bounds.push_back(v);
      }
    }
    // Octant index o = 4·(x high) + 2·(y high) + (z high); bounds[o], bounds[o + 1] delimit it.
    for (int oct = 0; oct < 8; ++oct) {
      const size_t b = static_cast<size_t>(bounds[oct] - pts.begin()),
                   e = static_cast<size_t>(bounds[oct + 1] - pts.begin());
      if (b == e) continue;
      // Low half [min, centre], high half [centre, max]: exact bounds, no rounding outside the parent.
      Eigen::AlignedBox3f child(cell.min(), c);
      for (int axis = 0; axis < 3; ++axis)
        if (oct & (4 >> axis)) child.min()[axis] = c[axis], child.max()[axis] = cell.max()[axis];
      const int child_id = Build(b, e, child, level + 1, name + static_cast<char>('0' + oct));
      nodes[id].children.push_back(child_id);
    }
    return id;
  }
};

}  // namespace

PointOctree BuildPointOctree(std::vector<TilePoint> points, const OctreeOptions& options) {
  options.Check();
  points.erase(std::remove_if(points.begin(), points.end(), [](const TilePoint& p) { return !p.position.allFinite(); }),
               points.end());
  PointOctree tree;
  tree.points = std::move(points);
  if (tree.points.empty()) return tree;
  Eigen::AlignedBox3f box;
  for (const auto& p : tree.points) box.extend(p.position);
  // A cube around the bounds (a little larger, so that no point sits on the far faces).
  const float size = std::max(box.sizes().maxCoeff(), 1e-6f) * 1.0001f;
  const Eigen::Vector3f c = box.center();
  Eigen::AlignedBox3f cube(c - Eigen::Vector3f::Constant(size / 2), c + Eigen::Vector3f::Constant(size / 2));
  Builder b{options, tree.points, tree.nodes, {}};
  b.Build(0, tree.points.size(), cube, 0, "0");
  return tree;
}

}  // namespace fmv3d::pipeline
