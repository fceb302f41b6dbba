#include "fmv3d/surface/mesh_cleanup.h"

#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/PointCloud.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "fmv3d/core/error.h"

namespace fmv3d::surface {
namespace {

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

}  // namespace

void ComponentOptions::Check() const {
  if (!(support_distance_cells > 0)) throw Error("mesh components: support distance must be positive");
  if (!(min_area_cells >= 0)) throw Error("mesh components: minimum area must be >= 0");
  if (!(min_support_density >= 0)) throw Error("mesh components: minimum support density must be >= 0");
}

size_t ComponentSelection::kept() const {
  return static_cast<size_t>(std::count_if(components.begin(), components.end(), [](const MeshComponent& c) {
    return c.decision == ComponentDecision::kKept;
  }));
}

size_t ComponentSelection::kept_faces() const {
  size_t n = 0;
  for (const auto& c : components) n += c.decision == ComponentDecision::kKept ? c.faces : 0;
  return n;
}

const char* ToString(ComponentDecision d) {
  switch (d) {
    case ComponentDecision::kKept:
      return "kept";
    case ComponentDecision::kTooFewPoints:
      return "too few points";
    case ComponentDecision::kTooSmall:
      return "too small";
    case ComponentDecision::kTooSparse:
      return "too sparse";
  }
  return "?";
}

const char* ToString(SurfaceKind k) { return k == SurfaceKind::kOpen ? "open" : "watertight"; }

MeshPieces FindPieces(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles) {
  std::vector<int> parent(vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& f : triangles) {
    for (int k = 0; k < 3; ++k) {
      if (f[k] < 0 || static_cast<size_t>(f[k]) >= vertices.size())
        throw Error("mesh components: a triangle indexes a vertex out of range");
    }
    const int a = Find(parent, f[0]);
    parent[Find(parent, f[1])] = a;
    parent[Find(parent, f[2])] = a;
  }
  MeshPieces out;
  std::vector<int> root_index(vertices.size(), -1);
  out.face_piece.resize(triangles.size());
  for (size_t i = 0; i < triangles.size(); ++i) {
    const auto& f = triangles[i];
    const int r = Find(parent, f[0]);
    if (root_index[r] < 0) {
      root_index[r] = static_cast<int>(out.faces.size());
      out.faces.push_back(0);
      out.area.push_back(0);
    }
    const int c = root_index[r];
    out.face_piece[i] = c;
    ++out.faces[c];
    out.area[c] += 0.5 * (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]).norm();
  }
  return out;
}

std::vector<int> MeshPieces::VertexPieces(const std::vector<Eigen::Vector3i>& triangles, size_t num_vertices) const {
  std::vector<int> out(num_vertices, -1);
  for (size_t i = 0; i < triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) out[triangles[i][k]] = face_piece[i];
  return out;
}

ComponentSelection SelectComponents(const std::vector<Eigen::Vector3d>& vertices,
                                    const std::vector<Eigen::Vector3i>& triangles,
                                    const std::vector<Eigen::Vector3d>& points, double cell, double spacing,
                                    const ComponentOptions& options, size_t max_points) {
  options.Check();
  if (!(cell > 0) || !(spacing > 0)) throw Error("mesh components: cell and spacing must be positive");
  ComponentSelection out;
  if (triangles.empty()) return out;
  const MeshPieces pieces = FindPieces(vertices, triangles);
  out.face_component = pieces.face_piece;
  out.components.resize(pieces.faces.size());
  for (size_t c = 0; c < pieces.faces.size(); ++c) {
    out.components[c].faces = pieces.faces[c];
    out.components[c].area = pieces.area[c];
  }
  const std::vector<int> vertex_component = pieces.VertexPieces(triangles, vertices.size());

  // Support: every (sub-sampled) point votes for the piece of its nearest vertex.
  if (!points.empty()) {
    open3d::geometry::PointCloud vc;
    vc.points_ = vertices;
    const open3d::geometry::KDTreeFlann tree(vc);
    const size_t n = std::min(points.size(), std::max<size_t>(max_points, 1));
    const double step = static_cast<double>(points.size()) / static_cast<double>(n);
    const double limit2 = std::pow(options.support_distance_cells * cell, 2);
    std::vector<int> vote(n, -1);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<int> idx;
      std::vector<double> d2;
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const auto& p = points[static_cast<size_t>(static_cast<double>(i) * step)];
        if (tree.SearchKNN(p, 1, idx, d2) > 0 && d2[0] <= limit2) vote[i] = vertex_component[idx[0]];
      }
    });
    std::vector<size_t> counts(out.components.size(), 0);
    for (int c : vote)
      if (c >= 0) ++counts[c];
    for (size_t c = 0; c < counts.size(); ++c)
      out.components[c].support = static_cast<size_t>(std::lround(static_cast<double>(counts[c]) * step));
  }

  size_t best = 0;
  for (size_t c = 0; c < out.components.size(); ++c) {
    MeshComponent& mc = out.components[c];
    if (mc.support > out.components[best].support) best = c;
    const double density = mc.area > 0 ? static_cast<double>(mc.support) * spacing * spacing / mc.area : 0;
    if (mc.support < options.min_support_points)
      mc.decision = ComponentDecision::kTooFewPoints;
    else if (mc.area < options.min_area_cells * cell * cell)
      mc.decision = ComponentDecision::kTooSmall;
    else if (density < options.min_support_density)
      mc.decision = ComponentDecision::kTooSparse;
  }
  out.components[best].decision = ComponentDecision::kKept;
  return out;
}

}  // namespace fmv3d::surface
