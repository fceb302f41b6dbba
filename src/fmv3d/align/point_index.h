// Nearest-neighbour queries on a 3D point set, and the per-point quantities registration needs from
// neighbourhoods: normals by local PCA and the median spacing.
// The index is our own static kd-tree (median splits on the widest axis, small leaves, exact k-NN with a
// bounded max-heap): Open3D's header-instantiated KDTreeFlann crashed in nanoflann's search here (the
// Debian library and our build disagree on something in its inline templates). Queries are const and
// thread-safe; the index keeps its own copy of the points.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

namespace fmv3d::align {

class PointIndex {
 public:
  explicit PointIndex(const std::vector<Eigen::Vector3d>& points);
  ~PointIndex();
  PointIndex(PointIndex&&) noexcept;
  PointIndex& operator=(PointIndex&&) noexcept;

  size_t size() const { return size_; }
  // Index of the closest point (−1 for an empty set); squared distance in *distance2 when given.
  int Nearest(const Eigen::Vector3d& query, double* distance2 = nullptr) const;
  // The k closest points, nearest first (fewer when the set is smaller).
  void Knn(const Eigen::Vector3d& query, int k, std::vector<int>* indices, std::vector<double>* distance2) const;

 private:
  struct Node {
    int begin = 0, end = 0;     // range of order_ (leaves) ...
    int left = -1, right = -1;  // ... or children (inner nodes)
    int axis = 0;
    double split = 0;
  };
  int Build(int begin, int end);
  void Search(int node, const Eigen::Vector3d& q, size_t k, std::vector<std::pair<double, int>>* heap) const;
  std::vector<Eigen::Vector3d> points_;  // in tree order
  std::vector<int> order_;               // tree order → original index
  std::vector<Node> nodes_;
  size_t size_ = 0;
};

// Unit normals by PCA of each point's k nearest neighbours (the eigenvector of the smallest eigenvalue).
// The sign is arbitrary (an unoriented normal); a point with fewer than 3 neighbours gets (0, 0, 1).
std::vector<Eigen::Vector3d> EstimateNormals(const std::vector<Eigen::Vector3d>& points, const PointIndex& index,
                                             int k = 20);

// Median distance of a sample of points to their nearest other point (a scale for thresholds); 0 when the
// set has fewer than 2 points.
double MedianSpacing(const std::vector<Eigen::Vector3d>& points, const PointIndex& index, size_t samples = 2000);

// Root mean square distance to the centroid (a robust-enough size of a point set for scale guesses).
double RmsRadius(const std::vector<Eigen::Vector3d>& points, Eigen::Vector3d* centroid = nullptr);

// Every `step`-th point so that at most `max_points` remain (all when max_points <= 0 or the set is smaller).
std::vector<int> EvenSubsample(size_t n, size_t max_points);

}  // namespace fmv3d::align
