// Binary glTF 2.0 (.glb) of a textured mesh, through tinygltf: one primitive per material (atlas page), its
// texture embedded as PNG. glTF wants one index per vertex, so a vertex is emitted once per distinct
// (position, uv) pair of the OBJ-style mesh. Texture coordinates are flipped to glTF's top-left origin;
// positions stay in the mesh's metres (glTF's +y up is not applied: viewers show z-up data lying down, which
// keeps the file in the same frame as every other output of the workspace).
#pragma once

#include <filesystem>

#include "fmv3d/io/mesh.h"

namespace fmv3d::surface {

// Every face needs texture coordinates; normals are written when every face has them.
void WriteGlb(const io::TexturedMesh& mesh, const std::filesystem::path& path);

}  // namespace fmv3d::surface
