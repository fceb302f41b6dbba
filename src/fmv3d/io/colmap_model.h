// COLMAP text model (cameras.txt, images.txt, points3D.txt): the interchange format for poses, so COLMAP's GUI,
// Gaussian-splatting and NeRF tools can read our models and we can read theirs.
// Cameras are written as COLMAP's OPENCV model (fx fy cx cy k1 k2 p1 p2), with fx = f·s_u, fy = f.
// Reading accepts SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV; other models are an error.
// Numbers are written with 17 significant digits, so write → read reproduces every double exactly.
#pragma once

#include <filesystem>

#include "fmv3d/core/reconstruction.h"

namespace fmv3d::io {

void WriteColmapText(const core::Reconstruction& rec, const std::filesystem::path& dir);
core::Reconstruction ReadColmapText(const std::filesystem::path& dir);

}  // namespace fmv3d::io
