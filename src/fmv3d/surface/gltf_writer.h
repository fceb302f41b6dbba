// Binary glTF 2.0 (.glb) of a textured mesh, through tinygltf: one primitive per material (atlas page), its
// texture embedded as PNG. glTF wants one index per vertex, so a vertex is emitted once per distinct
// (position, uv) pair of the OBJ-style mesh. Texture coordinates are flipped to glTF's top-left origin;
// positions stay in metres but are rotated -90 deg about x, (x, y, z) -> (x, z, -y), because glTF is +y up:
// without it viewers show our z-up model lying on its side. Every other workspace output stays z-up.
#pragma once

#include <filesystem>

#include "fmv3d/io/mesh.h"
#include "fmv3d/io/obj_io.h"

namespace fmv3d::surface {

// Every face needs texture coordinates; normals are written when every face has them. `textures`: the
// materials' PNG bytes when already encoded (io::EncodeTextures), else they are encoded here.
void WriteGlb(const io::TexturedMesh& mesh, const std::filesystem::path& path,
              const io::EncodedTextures* textures = nullptr);

}  // namespace fmv3d::surface
