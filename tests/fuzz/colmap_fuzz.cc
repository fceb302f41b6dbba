// libFuzzer target for the COLMAP text model reader (models from COLMAP, Gaussian-splatting tools, or ours). The
// input is cameras.txt, images.txt and points3D.txt joined by lines "%%fmv3d-fuzz-next-file%%". A model read
// must be consistent (every image's camera and every track's image exist); bad input throws fmv3d::Error.
#include <cstddef>
#include <cstdint>

#include "fmv3d/core/error.h"
#include "fmv3d/io/colmap_model.h"
// fuzz-sources: core/reconstruction.cc core/camera.cc core/pose.cc
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto parts = fmv3d::fuzz::SplitInput(data, size, 3);
  const char* names[3] = {"cameras.txt", "images.txt", "points3D.txt"};
  for (int i = 0; i < 3; ++i) fmv3d::fuzz::WriteScratch(names[i], parts[i].data(), parts[i].size());
  try {
    const auto rec = fmv3d::io::ReadColmapText(fmv3d::fuzz::ScratchDir());
    try {
      rec.Validate();
    } catch (const fmv3d::Error&) {
      __builtin_trap();  // the reader returned a model whose ids or tracks dangle
    }
    (void)rec.MeanReprojectionError();
  } catch (const fmv3d::Error&) {
  }
  return 0;
}
