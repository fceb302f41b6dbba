// Wavefront OBJ/MTL with texture coordinates, normals and diffuse texture maps (map_Kd).
// Reading: v, vt, vn, f (polygons are fan-triangulated, negative indices allowed), usemtl, mtllib; MTL:
// newmtl, Kd, map_Kd (textures are loaded with OpenCV when `load_textures` and the file exists). Other
// statements are ignored. Writing: `<stem>.obj`, `<stem>.mtl`, and every in-memory texture as a PNG beside
// them (named by the material's texture_file, or `<stem>_<material>.png`). Coordinates are written with 17
// significant digits, so write → read reproduces vertices exactly.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "fmv3d/io/mesh.h"

namespace fmv3d::io {

TexturedMesh ReadObj(const std::filesystem::path& path, bool load_textures = true);
// png_compression: 0..9 (OpenCV IMWRITE_PNG_COMPRESSION); large noise textures compress poorly, so the
// default favours speed.
void WriteObj(const TexturedMesh& mesh, const std::filesystem::path& path, int png_compression = 1);

// Every material's in-memory texture as PNG bytes (empty for a material without one), the pages encoded in
// parallel: a model written in several formats (OBJ, glTF) encodes its atlas once.
using EncodedTextures = std::vector<std::vector<uint8_t>>;
EncodedTextures EncodeTextures(const TexturedMesh& mesh, int png_compression = 1);
// Throws fmv3d::Error naming `path` unless `textures` has one entry per material of `mesh`.
void CheckEncodedTextures(const TexturedMesh& mesh, const EncodedTextures& textures, const std::filesystem::path& path);
// The same with the textures already encoded (one entry per material, as EncodeTextures gives).
void WriteObj(const TexturedMesh& mesh, const std::filesystem::path& path, const EncodedTextures& textures);

}  // namespace fmv3d::io
