// libFuzzer target for the PLY readers: our oriented point cloud (dense/fused.ply, sparse.ply) and others'
// (KWIVER landmarks, Open3D meshes), read by io::ReadPointCloudPly, and the coloured triangle mesh reader
// (mesh/poisson.ply). Whatever the bytes, a reader returns a consistent object or throws fmv3d::Error; any other
// exception, a crash or an ASan/UBSan report is a finding.
#include <cstddef>
#include <cstdint>

#include "fmv3d/core/error.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fmv3d::fuzz::WriteScratch("in.ply", reinterpret_cast<const char*>(data), size);
  try {
    const auto cloud = fmv3d::io::ReadPointCloudPly(path);
    cloud.Validate();
  } catch (const fmv3d::Error&) {
  }
  try {
    const auto mesh = fmv3d::surface::ReadMeshPly(path);
    try {
      mesh.Validate();
    } catch (const fmv3d::Error&) {
      __builtin_trap();  // the reader returned a mesh whose indices or attributes are inconsistent
    }
  } catch (const fmv3d::Error&) {
  }
  return 0;
}
