// PlyMesh: a mesh PLY read by our own reader (the surface stage's mesh/*.ply and other tools' meshes). Implemented
// in point_cloud.cc beside the cloud reader, whose element reader it shares.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "fmv3d/io/point_cloud.h"

namespace fmv3d::io {

// A PLY's vertices (read as ReadPointCloudPly reads them) and its faces as triangles.
struct PlyMesh {
  OrientedPointCloud vertices;
  std::vector<Eigen::Vector3i> triangles;
};

// Reads a mesh PLY (ascii or binary): the face element's `vertex_indices` (or `vertex_index`) lists, polygons
// split into a triangle fan (what other tools write is triangles or convex quads). Throws fmv3d::Error naming the
// file on a face with fewer than 3 vertices or an index outside the vertex element, so no caller ever sees an
// index it cannot use.
PlyMesh ReadMeshPly(const std::filesystem::path& path);

}  // namespace fmv3d::io
