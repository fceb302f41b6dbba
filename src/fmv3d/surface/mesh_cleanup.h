// Clean-up of a Poisson surface that keeps everything the dense points support and only that.
//
// Poisson closes every hole with a smooth membrane far from the samples; trimming that membrane (by the
// solver's sample density and by the distance to the points) leaves the true surface in pieces: the terrain,
// every building whose foot was not sampled, bridges, trees, and small blobs fitted to outlier points. Which
// piece to keep is decided per piece, on what supports it, never by its rank:
//   - support: the dense points whose nearest mesh vertex is on the piece (within `support_distance`);
//   - area, in octree cells² (the solver's resolution: a piece of a few cells is one outlier cluster);
//   - support density: points per sample-spacing² of area; a membrane piece that survived the trimming
//     (large area, few points) falls below `min_support_density`.
// A piece is kept when all three pass; the piece with the most support is always kept (a scene is never
// emptied by the rule).
//
// Density trimming: Open3D returns per vertex the solver's sample density. Vertices below a quantile of it go,
// except those within one cell of a point: a sparsely sampled but real surface (a far building, a facade
// seen at a grazing angle) has a low density everywhere, and a global quantile would cut it out whole.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <vector>

namespace fmv3d::surface {

// What the surface is meant to be: an open surface that ends where the points end (terrain, a town: the
// membrane Poisson adds is trimmed), or a closed one (an object captured from all round: no trimming, the
// solver's watertight surface, only the supported components kept).
enum class SurfaceKind { kOpen, kWatertight };

struct ComponentOptions {
  double support_distance_cells = 1.5;  // a point supports the piece of its nearest vertex within this × cell
  size_t min_support_points = 30;       // points on the piece
  double min_area_cells = 16;           // area in cells²
  double min_support_density = 0.01;    // supporting points per spacing² of area
  void Check() const;
};

enum class ComponentDecision { kKept, kTooFewPoints, kTooSmall, kTooSparse };

struct MeshComponent {
  size_t faces = 0;
  double area = 0;
  size_t support = 0;  // supporting points
  ComponentDecision decision = ComponentDecision::kKept;
};

struct ComponentSelection {
  std::vector<int> face_component;        // per triangle, index into components
  std::vector<MeshComponent> components;  // in order of their first face
  size_t kept() const;
  size_t kept_faces() const;
};

// Connected pieces of a mesh (triangles sharing a vertex), numbered in order of their first triangle. Throws
// fmv3d::Error when a triangle indexes a vertex out of range.
struct MeshPieces {
  std::vector<int> face_piece;  // per triangle
  std::vector<size_t> faces;    // per piece
  std::vector<double> area;     // per piece
  // Per vertex its piece, -1 for a vertex in no triangle.
  std::vector<int> VertexPieces(const std::vector<Eigen::Vector3i>& triangles, size_t num_vertices) const;
};
MeshPieces FindPieces(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles);

// Connected pieces (triangles sharing a vertex) of the mesh and the decision on each. `cell` is the octree
// cell width, `spacing` the points' median spacing (both > 0). Points are subsampled evenly to at most
// `max_points` for the support count (the counts are scaled back). Pure: no mesh is modified.
ComponentSelection SelectComponents(const std::vector<Eigen::Vector3d>& vertices,
                                    const std::vector<Eigen::Vector3i>& triangles,
                                    const std::vector<Eigen::Vector3d>& points, double cell, double spacing,
                                    const ComponentOptions& options, size_t max_points = 2000000);

const char* ToString(ComponentDecision d);
const char* ToString(SurfaceKind k);

}  // namespace fmv3d::surface
