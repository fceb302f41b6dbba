#include "fmv3d/align/point_index.h"

#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>

#include "fmv3d/core/stats.h"

namespace fmv3d::align {

namespace {
constexpr int kLeafSize = 12;
}

PointIndex::PointIndex(const std::vector<Eigen::Vector3d>& points) : points_(points), size_(points.size()) {
  order_.resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) order_[i] = static_cast<int>(i);
  if (!points.empty()) {
    nodes_.reserve(2 * points.size() / kLeafSize + 2);
    Build(0, static_cast<int>(points.size()));
    // Store the points in tree order so leaves are contiguous in memory.
    std::vector<Eigen::Vector3d> sorted(points.size());
    for (size_t i = 0; i < points.size(); ++i) sorted[i] = points[order_[i]];
    points_.swap(sorted);
  }
}

PointIndex::~PointIndex() = default;
PointIndex::PointIndex(PointIndex&&) noexcept = default;
PointIndex& PointIndex::operator=(PointIndex&&) noexcept = default;

int PointIndex::Build(int begin, int end) {
  const int id = static_cast<int>(nodes_.size());
  nodes_.push_back(Node{begin, end});
  if (end - begin <= kLeafSize) return id;
  Eigen::AlignedBox3d box;
  for (int i = begin; i < end; ++i) box.extend(points_[order_[i]]);
  int axis = 0;
  box.diagonal().maxCoeff(&axis);
  if (!(box.diagonal()[axis] > 0)) return id;  // all points equal: one leaf
  const int mid = begin + (end - begin) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int a, int b) { return points_[a][axis] < points_[b][axis]; });
  const double split = points_[order_[mid]][axis];
  const int left = Build(begin, mid);
  const int right = Build(mid, end);
  Node& n = nodes_[id];
  n.axis = axis;
  n.split = split;
  n.left = left;
  n.right = right;
  return id;
}

// heap: max-heap on squared distance of the best k so far.
void PointIndex::Search(int node, const Eigen::Vector3d& q, size_t k, std::vector<std::pair<double, int>>* heap) const {
  const Node& n = nodes_[node];
  if (n.left < 0) {
    for (int i = n.begin; i < n.end; ++i) {
      const double d2 = (points_[i] - q).squaredNorm();
      if (heap->size() < k) {
        heap->push_back({d2, i});
        std::push_heap(heap->begin(), heap->end());
      } else if (d2 < heap->front().first) {
        std::pop_heap(heap->begin(), heap->end());
        heap->back() = {d2, i};
        std::push_heap(heap->begin(), heap->end());
      }
    }
    return;
  }
  const double diff = q[n.axis] - n.split;
  const int near = diff < 0 ? n.left : n.right, far = diff < 0 ? n.right : n.left;
  Search(near, q, k, heap);
  if (heap->size() < k || diff * diff < heap->front().first) Search(far, q, k, heap);
}

int PointIndex::Nearest(const Eigen::Vector3d& query, double* distance2) const {
  if (size_ == 0 || !query.allFinite()) return -1;
  std::vector<std::pair<double, int>> heap;
  heap.reserve(1);
  Search(0, query, 1, &heap);
  if (distance2) *distance2 = heap.front().first;
  return order_[heap.front().second];
}

void PointIndex::Knn(const Eigen::Vector3d& query, int k, std::vector<int>* indices,
                     std::vector<double>* distance2) const {
  indices->clear();
  distance2->clear();
  if (size_ == 0 || k <= 0 || !query.allFinite()) return;
  std::vector<std::pair<double, int>> heap;
  heap.reserve(k);
  Search(0, query, static_cast<size_t>(k), &heap);
  std::sort_heap(heap.begin(), heap.end());
  for (const auto& [d2, i] : heap) {
    indices->push_back(order_[i]);
    distance2->push_back(d2);
  }
}

std::vector<Eigen::Vector3d> EstimateNormals(const std::vector<Eigen::Vector3d>& points, const PointIndex& index,
                                             int k) {
  std::vector<Eigen::Vector3d> normals(points.size(), Eigen::Vector3d::UnitZ());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> nn;
    std::vector<double> d2;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      index.Knn(points[i], k, &nn, &d2);
      if (nn.size() < 3) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int j : nn) mean += points[j];
      mean /= nn.size();
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (int j : nn) cov += (points[j] - mean) * (points[j] - mean).transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
      const Eigen::Vector3d n = es.eigenvectors().col(0);
      if (n.allFinite() && n.norm() > 0.5) normals[i] = n.normalized();
    }
  });
  return normals;
}

double MedianSpacing(const std::vector<Eigen::Vector3d>& points, const PointIndex& index, size_t samples) {
  if (points.size() < 2) return 0;
  const auto pick = EvenSubsample(points.size(), samples);
  std::vector<double> d;
  d.reserve(pick.size());
  std::vector<int> nn;
  std::vector<double> d2;
  for (int i : pick) {
    index.Knn(points[i], 2, &nn, &d2);
    if (d2.size() == 2) d.push_back(std::sqrt(d2[1]));
  }
  return core::Median(std::move(d));
}

double RmsRadius(const std::vector<Eigen::Vector3d>& points, Eigen::Vector3d* centroid) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : points) c += p;
  if (!points.empty()) c /= points.size();
  double s = 0;
  for (const auto& p : points) s += (p - c).squaredNorm();
  if (centroid) *centroid = c;
  return points.empty() ? 0 : std::sqrt(s / points.size());
}

std::vector<int> EvenSubsample(size_t n, size_t max_points) {
  std::vector<int> out;
  if (max_points == 0 || n <= max_points) {
    out.resize(n);
    for (size_t i = 0; i < n; ++i) out[i] = static_cast<int>(i);
    return out;
  }
  out.reserve(max_points);
  // Evenly spread picks (not every k-th with a remainder bias): i·n/max_points.
  for (size_t i = 0; i < max_points; ++i) out.push_back(static_cast<int>(i * n / max_points));
  return out;
}

}  // namespace fmv3d::align
