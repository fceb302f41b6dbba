// Binary glTF 2.0 (.glb) of a textured mesh, through tinygltf: one primitive per material (atlas page), its
// texture embedded as PNG. glTF wants one index per vertex, so a vertex is emitted once per distinct
// (position, uv) pair of the OBJ-style mesh. Texture coordinates are flipped to glTF's top-left origin;
// positions stay in metres but are rotated -90 deg about x, (x, y, z) -> (x, z, -y), because glTF is +y up:
// without it viewers show our z-up model lying on its side. Every other workspace output stays z-up.
#pragma once

#include <filesystem>

#include "fmv3d/io/mesh.h"

namespace fmv3d::surface {

// Every face needs texture coordinates; normals are written when every face has them.
void WriteGlb(const io::TexturedMesh& mesh, const std::filesystem::path& path);

}  // namespace fmv3d::surface
