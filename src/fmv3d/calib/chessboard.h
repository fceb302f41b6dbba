// Chessboard calibration (`fmv3d calibrate`): corner detection with sub-pixel refinement, then OpenCV's
// calibrateCamera restricted to the seed's model — f, s_u (aspect), u0, v0, k1, k2, p1, p2 (k3 fixed at 0,
// aspect free) — with per-image reprojection RMS and the parameters' standard deviations.
//
// Pixel convention: results are in fmv3d's convention (pixel centres at +0.5, see core/camera.h); corners
// returned by DetectChessboard are in OpenCV's (integer centres), as drawn on the corner images.
#pragma once

#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"

namespace fmv3d::calib {

struct BoardSpec {
  int cols = 9, rows = 6;  // inner corners
  double square = 0.025;   // side of a square, metres (only scales the board poses)
  // Parses "9x6". Throws fmv3d::Error on anything else.
  static BoardSpec Parse(const std::string& text, double square);
  void Check() const;
};

struct BoardDetection {
  std::string name;  // image file name (for reports)
  cv::Size image_size;
  bool found = false;
  std::vector<cv::Point2f> corners;  // OpenCV pixel convention, row-major over the board
};

// Finds the board's inner corners (sector-based detector, falling back to the classic one) and refines
// them to sub-pixel accuracy.
BoardDetection DetectChessboard(const cv::Mat& image, const BoardSpec& board, const std::string& name = "");

struct CalibrationResult {
  core::Camera camera;                                // fmv3d convention
  std::array<double, core::kNumIntrinsics> stddev{};  // same order as Camera::Params()
  double rms = 0;                                     // over all corners of all used images, pixels
  std::vector<std::string> used;                      // image names, in order
  std::vector<double> per_image_rms;                  // parallel to used
  // Parallel to used: the detected corners (fmv3d convention, +0.5) and their reprojection residuals
  // (reprojected − detected, pixels), row-major over the board — what the console's calibration window draws.
  std::vector<std::vector<Eigen::Vector2d>> corners, residuals;
  std::vector<std::string> rejected;  // board not found
  BoardSpec board;
};

// Calibrates from the detections where the board was found. Throws fmv3d::Error with fewer than 3 views or
// views of different sizes.
CalibrationResult Calibrate(const std::vector<BoardDetection>& detections, const BoardSpec& board);

// Distortion field: displacement vectors (distorted − undistorted position) on a grid, exaggerated, with
// the principal point marked — the seed's Figure 2.
cv::Mat DrawDistortionField(const core::Camera& camera, double exaggeration = 10, int grid_cells = 20);
// The image with the detected corners drawn (green when found, red partial pattern when not).
cv::Mat DrawCorners(const cv::Mat& image, const BoardDetection& detection, const BoardSpec& board);

}  // namespace fmv3d::calib
