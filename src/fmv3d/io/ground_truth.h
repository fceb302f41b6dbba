// Readers for the ground-truth camera formats of public benchmark data, converted to our Reconstruction (and
// from there to a COLMAP text model) so `fmv3d evaluate-sparse --truth` can compare against them.
//
// All three formats use OpenCV's pixel convention (pixel centres at integers); the principal point is shifted by
// +0.5 px into ours (core/camera.h). Cameras with identical K and size share one camera id.
#pragma once

#include <filesystem>

#include "fmv3d/core/reconstruction.h"

namespace fmv3d::io {

// Strecha et al. (fountain-P11, Herz-Jesus-P8): a folder of NAME.camera files, each with K (3 rows), radial
// distortion (1 row), R (3 rows, camera-to-world), camera centre C (1 row), width height. Image name = NAME.
core::Reconstruction ReadStrechaCameras(const std::filesystem::path& dir);

// Middlebury multi-view (*_par.txt): first line the count, then per image: name, K (9, row-major), R (9,
// world-to-camera), t (3). Image size is read from the image beside the file when present, else 640x480.
core::Reconstruction ReadMiddleburyPar(const std::filesystem::path& par_file);

// KWIVER KRTD folder: one <stem>-<N>.krtd per frame with K (3 rows), R (3 rows, world-to-camera), t (1 row),
// distortion (1 row: k1 [k2 [p1 p2]]). Frame N is renamed to our frame name "<stem>-<N - index_offset, 6 digits>
// <ext>" (KWIVER numbers video frames from 1; ours count from 0). width/height give the image size.
core::Reconstruction ReadKrtdFolder(const std::filesystem::path& dir, int width, int height, int index_offset = 1,
                                    const std::string& ext = ".png");

}  // namespace fmv3d::io
