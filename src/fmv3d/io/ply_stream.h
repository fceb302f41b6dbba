// Streaming read of a PLY file's vertices (binary little-endian, as fmv3d and most tools write it): one callback
// per vertex with its position, normal, colour, number of views and σ, without holding the cloud in memory — for
// consumers of clouds too large to load whole (the 3D Tiles writer). Extra properties, lists included (fused.ply's
// visibility), are skipped.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>

namespace fmv3d::io {

struct PlyVertex {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // zero when the file has no nx ny nz
  uint8_t rgb[3] = {0, 0, 0};
  uint8_t views = 0;  // length of the "visibility" list (images that see the point), capped at 255; 0 without
  float sigma = 0;    // the "sigma" property (stated uncertainty along the normal, mvs/fusion.h); 0 without
};

// Returns the vertex count announced by the header before the first callback through `on_count` (may be null).
// Returns false without reading vertices when the file is a PLY this reader does not stream (ASCII, big-endian,
// vertex not the first element): read it with ReadPointCloudPly instead. Throws fmv3d::Error naming the file
// when it cannot be opened, its header is malformed or it ends early.
bool StreamPlyVertices(const std::filesystem::path& path, const std::function<void(size_t count)>& on_count,
                       const std::function<void(const PlyVertex&)>& on_vertex);

}  // namespace fmv3d::io
