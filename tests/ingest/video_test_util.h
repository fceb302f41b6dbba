// Test helpers for the frames stage: procedurally drawn textures and a small FFmpeg encoder, so test videos
// are generated at test time (nothing binary is committed).
#pragma once

#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <string>

namespace fmv3d::test {

// A large random texture with structure at several scales (blobs, edges, corners) for KLT and SIFT.
cv::Mat RandomTexture(int width, int height, unsigned seed);

// The view of `texture` through a window of size out_size centred at (cx, cy) and scaled by zoom
// (zoom > 1 magnifies) and rotated by angle (radians), with sub-pixel positioning (bilinear). A texture
// point t appears at centre + zoom · R(-angle) (t - c).
cv::Mat ViewOf(const cv::Mat& texture, cv::Size out_size, double cx, double cy, double zoom = 1.0, double angle = 0.0);

// Encodes n frames produced by frame(i) (BGR, all the same size) with an FFmpeg encoder ("mpeg4", "ffv1",
// "libx264", "mpeg2video", "gif", "mjpeg") into `path` (container from its extension). Throws on failure.
void EncodeVideo(const std::filesystem::path& path, int n, double fps, const std::function<cv::Mat(int)>& frame,
                 const std::string& codec = "mpeg4", int gop = 12, int sar_num = 1, int sar_den = 1);

// Copies the first `fraction` of a file's bytes (a truncated video).
void TruncateCopy(const std::filesystem::path& from, const std::filesystem::path& to, double fraction);

}  // namespace fmv3d::test
