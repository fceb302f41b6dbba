// Calibration files: our camera.json (written by `fmv3d calibrate`, read by `fmv3d frames --camera`) and the
// OpenCV YAML/XML form (camera_matrix + distortion_coefficients + image_width/height), both ways.
//
// camera.json: { "version": 1, "model": "fmv3d-brown", "width", "height", "f", "aspect", "u0", "v0",
//                "k1", "k2", "p1", "p2", "pixel_convention": "pixel centres at +0.5",
//                "stddev": {...same keys...}, "rms": px, "rejected": [...],
//                "images": [{"name", "rms", "corners": [x0,y0,x1,y1,...] (detected, +0.5 convention),
//                            "residuals": [dx0,dy0,...] (reprojected − detected, px)}],
//                "board": {"cols", "rows", "square"} }
// The OpenCV file uses OpenCV's convention (integer pixel centres): cx = u0 − 0.5.
#pragma once

#include <filesystem>

#include "fmv3d/calib/chessboard.h"
#include "fmv3d/core/camera.h"

namespace fmv3d::calib {

void WriteCameraJson(const std::filesystem::path& path, const CalibrationResult& result);
void WriteOpenCvYaml(const std::filesystem::path& path, const core::Camera& camera, double rms = -1);
// Reads camera.json, or an OpenCV .yaml/.yml/.xml calibration. Throws fmv3d::Error naming the file.
core::Camera ReadCameraFile(const std::filesystem::path& path);

// The same lens at another resolution of the same aspect ratio (e.g. a calibration at 4000x3000 used for
// 1920x1440 frames). Returns false when the aspect ratios differ by more than 1%.
bool ScaleCamera(const core::Camera& camera, int width, int height, core::Camera* out);

}  // namespace fmv3d::calib
