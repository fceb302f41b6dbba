// Per-view depth + normal map (the output of PatchMatch, the input of fusion) and its files.
//
// File `<stem>.dmap` (little-endian): magic "FMVDMAP\0", uint32 version (1), int32 width, int32 height, then
// width·height float depths, 3·width·height float normals (x y z interleaved), width·height float costs.
// Depth is the camera-frame z at the pixel centre of the undistorted working-resolution view, 0 = no depth;
// normals are unit vectors in the camera frame, pointing towards the camera. Cost is 1 − NCC (0 best, 2 worst).
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>

namespace fmv3d::mvs {

struct DepthMap {
  cv::Mat depth;   // CV_32F
  cv::Mat normal;  // CV_32FC3
  cv::Mat cost;    // CV_32F
  int width() const { return depth.cols; }
  int height() const { return depth.rows; }
  bool empty() const { return depth.empty(); }
  // Number of pixels with a depth.
  int CountValid() const;
};

void WriteDepthMap(const DepthMap& map, const std::filesystem::path& path);
// Throws fmv3d::Error naming the file when it is not a depth map of this version or is truncated.
DepthMap ReadDepthMap(const std::filesystem::path& path);
// False-colour previews: depth (turbo colour map from near = blue to far = red, 2nd to 98th percentile; black = none)
// and normals (RGB = 0.5·(n + 1); black = none).
void WriteDepthPreview(const DepthMap& map, const std::filesystem::path& depth_png,
                       const std::filesystem::path& normal_png);

}  // namespace fmv3d::mvs
