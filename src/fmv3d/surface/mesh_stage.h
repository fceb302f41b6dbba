// The `fmv3d mesh WS` stage: WS/dense/fused.ply (oriented points) → screened Poisson + clean-up (poisson.h) →
//   WS/mesh/poisson.ply    binary PLY: vertices with normals and colours, triangles (colored_mesh.h)
//   WS/report/mesh.json    point count and spacing, octree depth, counts after each clean-up step, timings.
// A cloud without normals gets normals estimated from its neighbours (Open3D) and oriented towards the
// cameras of its visibility list (WS/sparse), with a warning; without visibility that is an error.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/workspace.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/surface/poisson.h"

namespace fmv3d::surface {

struct MeshStageOptions {
  PoissonOptions poisson;
  bool estimate_missing_normals = true;  // false: a cloud without normals is an error
  int normal_neighbours = 16;            // k of the normal estimation
  void Check() const;
};

// Estimates unit normals (k nearest neighbours) and orients each towards the mean centre of the cameras
// that see the point. Throws fmv3d::Error when the cloud has no visibility or names an unknown image.
void EstimateNormalsTowardsCameras(io::OrientedPointCloud* cloud, const std::filesystem::path& sparse_dir, int k);

// Returns the summary also written to WS/report/mesh.json. Throws fmv3d::Error naming the missing input and
// the command that makes it, or the problem with the cloud.
nlohmann::json RunMeshStage(const core::Workspace& workspace, const MeshStageOptions& options);

}  // namespace fmv3d::surface
