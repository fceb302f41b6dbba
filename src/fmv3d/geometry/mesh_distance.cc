#include "fmv3d/geometry/mesh_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::geometry {

struct MeshDistance::Node {
  Eigen::AlignedBox3d box;
  int left = -1, right = -1;  // children (inner node) or -1
  int begin = 0, end = 0;     // range of order_ (leaf)
};

namespace {
constexpr int kLeafSize = 4;

double BoxDistanceSq(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& p) {
  const Eigen::Vector3d d = (box.min() - p).cwiseMax(p - box.max()).cwiseMax(0.0);
  return d.squaredNorm();
}
}  // namespace

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c) {
  // Voronoi-region walk: vertex regions, then edge regions, else the interior.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) return a;  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  return a + ab * v + ac * w;
}

MeshDistance::MeshDistance(std::vector<Eigen::Vector3d> vertices, std::vector<Eigen::Vector3i> triangles)
    : vertices_(std::move(vertices)), triangles_(std::move(triangles)) {
  for (const auto& t : triangles_)
    for (int k = 0; k < 3; ++k)
      if (t[k] < 0 || t[k] >= static_cast<int>(vertices_.size()))
        throw Error("mesh distance: triangle vertex index out of range");
  Build();
}

static std::vector<Eigen::Vector3i> TrianglesOf(const io::TexturedMesh& mesh) {
  std::vector<Eigen::Vector3i> t;
  t.reserve(mesh.faces.size());
  for (const auto& f : mesh.faces) t.emplace_back(f.v[0], f.v[1], f.v[2]);
  return t;
}

MeshDistance::MeshDistance(const io::TexturedMesh& mesh) : MeshDistance(mesh.vertices, TrianglesOf(mesh)) {}
MeshDistance::~MeshDistance() = default;
MeshDistance::MeshDistance(MeshDistance&&) noexcept = default;

void MeshDistance::Build() {
  nodes_.clear();
  order_.resize(triangles_.size());
  for (size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  if (triangles_.empty()) return;
  std::vector<Eigen::Vector3d> centroid(triangles_.size());
  std::vector<Eigen::AlignedBox3d> tri_box(triangles_.size());
  for (size_t i = 0; i < triangles_.size(); ++i) {
    const auto& t = triangles_[i];
    tri_box[i].setEmpty();
    for (int k = 0; k < 3; ++k) tri_box[i].extend(vertices_[t[k]]);
    centroid[i] = tri_box[i].center();
  }
  nodes_.reserve(2 * triangles_.size() / kLeafSize + 2);
  // Iterative build: split the longest axis of the centroid box at the median.
  struct Task {
    int node, begin, end;
  };
  std::vector<Task> stack;
  nodes_.push_back({});
  stack.push_back({0, 0, static_cast<int>(order_.size())});
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    Eigen::AlignedBox3d box, cbox;
    box.setEmpty();
    cbox.setEmpty();
    for (int i = task.begin; i < task.end; ++i) {
      box.extend(tri_box[order_[i]]);
      cbox.extend(centroid[order_[i]]);
    }
    nodes_[task.node].box = box;
    if (task.end - task.begin <= kLeafSize) {
      nodes_[task.node].begin = task.begin;
      nodes_[task.node].end = task.end;
      continue;
    }
    int axis;
    cbox.sizes().maxCoeff(&axis);
    const int mid = (task.begin + task.end) / 2;
    std::nth_element(order_.begin() + task.begin, order_.begin() + mid, order_.begin() + task.end,
                     [&](int a, int b) { return centroid[a][axis] < centroid[b][axis]; });
    const int left = static_cast<int>(nodes_.size());
    nodes_.push_back({});
    nodes_.push_back({});
    nodes_[task.node].left = left;
    nodes_[task.node].right = left + 1;
    stack.push_back({left, task.begin, mid});
    stack.push_back({left + 1, mid, task.end});
  }
}

ClosestPoint MeshDistance::Closest(const Eigen::Vector3d& p, double max_distance) const {
  ClosestPoint best;
  best.distance = std::numeric_limits<double>::infinity();
  double best_sq = max_distance > 0 ? max_distance * max_distance : std::numeric_limits<double>::infinity();
  if (nodes_.empty()) return best;
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (BoxDistanceSq(node.box, p) > best_sq) continue;
    if (node.left < 0) {
      for (int i = node.begin; i < node.end; ++i) {
        const auto& t = triangles_[order_[i]];
        const Eigen::Vector3d q = ClosestPointOnTriangle(p, vertices_[t[0]], vertices_[t[1]], vertices_[t[2]]);
        const double d = (q - p).squaredNorm();
        if (d <= best_sq) {
          best_sq = d;
          best.point = q;
          best.face = order_[i];
        }
      }
      continue;
    }
    // Visit the nearer child first (pushed last).
    const double dl = BoxDistanceSq(nodes_[node.left].box, p), dr = BoxDistanceSq(nodes_[node.right].box, p);
    if (top + 2 > 128) throw Error("mesh distance: tree too deep");
    if (dl < dr) {
      stack[top++] = node.right;
      stack[top++] = node.left;
    } else {
      stack[top++] = node.left;
      stack[top++] = node.right;
    }
  }
  if (best.face >= 0) {
    best.distance = std::sqrt(best_sq);
    const double side = Normal(best.face).dot(p - best.point);
    best.signed_distance = side < 0 ? -best.distance : best.distance;
  }
  return best;
}

double MeshDistance::Area(int face) const {
  const auto& t = triangles_.at(face);
  return 0.5 * (vertices_[t[1]] - vertices_[t[0]]).cross(vertices_[t[2]] - vertices_[t[0]]).norm();
}

Eigen::Vector3d MeshDistance::Normal(int face) const {
  const auto& t = triangles_.at(face);
  const Eigen::Vector3d n = (vertices_[t[1]] - vertices_[t[0]]).cross(vertices_[t[2]] - vertices_[t[0]]);
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

std::vector<Eigen::Vector3d> MeshDistance::SampleSurface(double spacing, std::vector<int>* faces, uint64_t seed) const {
  if (!(spacing > 0)) throw Error("mesh distance: sample spacing must be positive");
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<Eigen::Vector3d> out;
  if (faces) faces->clear();
  const double per_area = 1.0 / (spacing * spacing);
  for (size_t f = 0; f < triangles_.size(); ++f) {
    // Expected count = area / spacing²; the fractional part is drawn so small faces still get samples.
    const double expected = Area(static_cast<int>(f)) * per_area;
    int n = static_cast<int>(expected);
    if (uni(rng) < expected - n) ++n;
    const auto& t = triangles_[f];
    for (int k = 0; k < n; ++k) {
      double r1 = std::sqrt(uni(rng)), r2 = uni(rng);
      out.push_back((1 - r1) * vertices_[t[0]] + r1 * (1 - r2) * vertices_[t[1]] + r1 * r2 * vertices_[t[2]]);
      if (faces) faces->push_back(static_cast<int>(f));
    }
  }
  return out;
}

}  // namespace fmv3d::geometry
