// ColoredMesh: the surface stage's triangle mesh (WS/mesh/poisson.ply) — positions, per-vertex unit normals
// and RGB colours, counter-clockwise triangles seen from outside (normals of (b − a) × (c − a) point to the
// side the cameras saw).
//
// PLY written (binary little-endian; opened by MeshLab, CloudCompare, Blender, Open3D):
//   element vertex N: float x y z, float nx ny nz, uchar red green blue
//   element face M:   list uchar int vertex_indices
// The reader accepts any mesh PLY (io::ReadMeshPly: polygons as triangle fans); normals and colours are empty when the
// file has none.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <vector>

#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::surface {

struct ColoredMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3f> normals;  // empty or one per vertex
  std::vector<io::Rgb8> colors;          // RGB; empty or one per vertex
  std::vector<Eigen::Vector3i> triangles;

  bool empty() const { return triangles.empty(); }
  Eigen::AlignedBox3d Bounds() const;
  double SurfaceArea() const;
  // Area-weighted vertex normals from the triangles (replaces `normals`).
  void ComputeVertexNormals();
  // Throws fmv3d::Error when an index or an attribute count is inconsistent.
  void Validate() const;
  // The geometry as an untextured io::TexturedMesh (for the renderer and geometry::MeshDistance).
  io::TexturedMesh ToTexturedMesh() const;
};

void WriteMeshPly(const ColoredMesh& mesh, const std::filesystem::path& path);
// Throws fmv3d::Error naming the file when it cannot be read or holds no triangles.
ColoredMesh ReadMeshPly(const std::filesystem::path& path);

}  // namespace fmv3d::surface
