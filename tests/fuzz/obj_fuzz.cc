// libFuzzer target for the Wavefront OBJ/MTL reader (CAD models for `fmv3d compare`, our textured meshes). The
// input is the OBJ, then a line "%%fmv3d-fuzz-next-file%%", then the MTL written as in.mtl beside it (seeds say
// `mtllib in.mtl`). The mesh read must index only what it holds; bad input throws fmv3d::Error and nothing else.
#include <cstddef>
#include <cstdint>

#include "fmv3d/core/error.h"
#include "fmv3d/io/obj_io.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto parts = fmv3d::fuzz::SplitInput(data, size, 2);
  const auto obj = fmv3d::fuzz::WriteScratch("in.obj", parts[0].data(), parts[0].size());
  fmv3d::fuzz::WriteScratch("in.mtl", parts[1].data(), parts[1].size());
  try {
    const auto mesh = fmv3d::io::ReadObj(obj, /*load_textures=*/false);
    for (const auto& f : mesh.faces)
      for (int k = 0; k < 3; ++k) {
        if (f.v[k] < 0 || static_cast<size_t>(f.v[k]) >= mesh.vertices.size()) __builtin_trap();
        if (f.vt[k] >= static_cast<int>(mesh.uvs.size()) || f.vn[k] >= static_cast<int>(mesh.normals.size()))
          __builtin_trap();
        if (f.material >= static_cast<int>(mesh.materials.size())) __builtin_trap();
      }
    (void)mesh.Bounds();
  } catch (const fmv3d::Error&) {
  }
  return 0;
}
