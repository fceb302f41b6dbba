// Distance from points to a triangle mesh: the yardstick of every accuracy figure against a true or CAD
// surface (dense cloud vs synthetic scene, Poisson mesh vs CAD, DSM vs truth). An axis-aligned bounding-box
// tree over the triangles answers closest-point queries in O(log n); queries are const and thread-safe.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "fmv3d/io/mesh.h"

namespace fmv3d::geometry {

struct ClosestPoint {
  double distance = 0;    // Euclidean distance to the closest point on the mesh
  Eigen::Vector3d point;  // that closest point
  int face = -1;          // its triangle index
  // Signed distance: + on the side the face normal points to ((b − a) × (c − a), outwards for a closed,
  // counter-clockwise mesh), − behind it.
  double signed_distance = 0;
};

class MeshDistance {
 public:
  MeshDistance(std::vector<Eigen::Vector3d> vertices, std::vector<Eigen::Vector3i> triangles);
  explicit MeshDistance(const io::TexturedMesh& mesh);
  ~MeshDistance();
  MeshDistance(MeshDistance&&) noexcept;

  // Closest point of the mesh to p. max_distance prunes the search: beyond it, face = -1 and distance = inf.
  ClosestPoint Closest(const Eigen::Vector3d& p, double max_distance = -1) const;

  size_t num_triangles() const { return triangles_.size(); }
  const std::vector<Eigen::Vector3d>& vertices() const { return vertices_; }
  const std::vector<Eigen::Vector3i>& triangles() const { return triangles_; }
  double Area(int face) const;
  Eigen::Vector3d Normal(int face) const;  // unit, zero for a degenerate triangle

  // Points spread uniformly over the surface, about `spacing` apart (each triangle gets a count of samples
  // proportional to its area; deterministic for a seed). Used for completeness: how much of the true
  // surface has a reconstructed point near it.
  std::vector<Eigen::Vector3d> SampleSurface(double spacing, std::vector<int>* faces = nullptr,
                                             uint64_t seed = 1) const;

 private:
  struct Node;
  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Eigen::Vector3i> triangles_;
  std::vector<Node> nodes_;
  std::vector<int> order_;  // triangle indices, leaves reference ranges of it
  void Build();
};

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c);

}  // namespace fmv3d::geometry
