// The sparse model as the console's 3D view reads it (GET /api/workspaces/{ws}/cameras and /sparse): cameras
// with their intrinsics, pose and reprojection error, and the sparse points as flat arrays. Model frame
// (WS/sparse), the frame of dense/fused.ply and of tiles/ before the tileset's root transform.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/reconstruction.h"

namespace fmv3d::server {

// [{"name", "width", "height", "fx", "fy", "cx", "cy", "center", "rotation" (wxyz, world-to-camera),
//   "reprojection_rms_px" (null without observations), "frame": "frames/NAME"}], by image id.
nlohmann::json CamerasJson(const core::Reconstruction& rec);
// {"count", "positions": [x,y,z,...], "colors": [r,g,b,...], "errors": [px,...]}.
nlohmann::json SparseJson(const core::Reconstruction& rec);

}  // namespace fmv3d::server
