// `fmv3d tiles WS`: OGC 3D Tiles 1.0 for the console and any 3D Tiles client (CesiumJS, 3DTilesRendererJS).
//
// Input:  WS/dense/fused.ply (the dense cloud), WS/mesh/model.glb (the textured mesh, when present),
//         WS/geo/georef.json (when the workspace is georeferenced)
// Output: WS/tiles/tileset.json   asset.version "1.0"; the root (no content, refine ADD) has two children: the
//                                 point octree (point_octree.h) and the mesh tile
//         WS/tiles/points/N.pnts  one tile per octree node (io/tiles3d.h), N the node's octant path
//         WS/tiles/mesh/model.b3dm the GLB as a Batched 3D Model
// Everything is in the model frame (that of WS/sparse); when georeferenced, the root's `transform` maps it to
// ECEF (georef.json's similarity into ENU, then ENU at the origin into ECEF on WGS84; an MSL origin height is
// raised by the EGM96 undulation when PROJ's grid is installed).
// fused.ply is streamed into 32-byte tile points (io/ply_stream.h; other PLY flavours are read whole), so a
// 10 M-point cloud costs ~450 MB. Point tiles carry the batch table "views" and "sigma" when fused.ply has them.
// Geometric error: a node's subsample spacing on a surface, cell size / √budget, times 2; halving per level, 0 for
// leaves and the mesh. The tileset is written to WS/tiles.tmp and renamed, so WS/tiles is never half-made.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/workspace.h"
#include "fmv3d/pipeline/point_octree.h"

namespace fmv3d::pipeline {

struct TilesOptions {
  OctreeOptions octree;
};

// Writes the .pnts tiles of `tree` into dir/points/ and returns the point subtree's tile JSON (root node first).
nlohmann::json WritePointTiles(const PointOctree& tree, const std::filesystem::path& dir);

// ENU at (lat, lon, h on WGS84) → ECEF, as a 4x4 matrix.
Eigen::Matrix4d EnuToEcef(double lat_deg, double lon_deg, double height);

// The whole stage on a workspace; returns its summary (points, tiles, levels, seconds). Throws fmv3d::Error
// when WS/dense/fused.ply is missing or empty.
nlohmann::json RunTilesStage(const core::Workspace& ws, const TilesOptions& options);

}  // namespace fmv3d::pipeline
