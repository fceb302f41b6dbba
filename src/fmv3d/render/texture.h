// Mip-mapped texture with trilinear filtering, for the rasteriser.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

namespace fmv3d::render {

class MipTexture {
 public:
  MipTexture() = default;
  // bgr: CV_8UC3. Builds the pyramid by 2x2 box filtering (odd sizes round up, the last row/column repeat),
  // at most `max_levels` levels (1: the texture alone, for sampling at lod 0 only).
  explicit MipTexture(const cv::Mat& bgr, int max_levels = 64);

  bool empty() const { return levels_.empty(); }
  int width() const { return levels_.empty() ? 0 : levels_[0].w; }
  int height() const { return levels_.empty() ? 0 : levels_[0].h; }
  int num_levels() const { return static_cast<int>(levels_.size()); }

  // Colour (BGR, 0..255) at OBJ texture coordinates (u, v) (v = 0 at the bottom row), trilinear between
  // mip levels floor(lod) and floor(lod)+1; lod = log2(texels per pixel). Coordinates outside [0, 1] wrap.
  Eigen::Vector3f Sample(float u, float v, float lod) const;

 private:
  struct Level {
    int w = 0, h = 0;
    float fw = 0, fh = 0;  // texels across the unit u, v range (the level-0 size / 2^level)
    int tiles_x = 0;
    // 4 bytes per texel (B, G, R, unused), stored in 32x32-texel tiles (4 KiB, one page): a bilinear
    // footprint walking across a large texture in any direction then stays within few pages and cache
    // lines (row-major storage made the shading pass TLB-bound). A cv::Mat (a row of tiles per row) for OpenCV's
    // allocator, which puts large blocks on huge pages (io/huge_pages.h): faulting in an atlas's levels page by
    // page took most of an orthophoto's time.
    cv::Mat bgr;
    size_t Offset(int x, int y) const {
      return ((size_t(y >> 5) * tiles_x + (x >> 5)) << 12) + ((y & 31) << 7) + ((x & 31) << 2);
    }
  };
  Eigen::Vector3f Bilinear(const Level& l, float u, float v) const;
  std::vector<Level> levels_;
};

// Inline: these run once or twice per shaded pixel.
inline Eigen::Vector3f MipTexture::Bilinear(const Level& l, float u, float v) const {
  // Texel centres at (i + 0.5) / span; v flipped (OBJ convention); coordinates wrap (period: the texture).
  u -= std::floor(u);
  v -= std::floor(v);
  const float x = u * l.fw - 0.5f, y = (1.0f - v) * l.fh - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (x0 < 0 || x0 >= l.w) x0 = ((x0 % l.w) + l.w) % l.w;
  if (y0 < 0 || y0 >= l.h) y0 = ((y0 % l.h) + l.h) % l.h;
  const int x1 = x0 + 1 < l.w ? x0 + 1 : 0, y1 = y0 + 1 < l.h ? y0 + 1 : 0;
  const uint8_t* data = l.bgr.data;
  const uint8_t* p00 = data + l.Offset(x0, y0);
  const uint8_t* p01 = data + l.Offset(x1, y0);
  const uint8_t* p10 = data + l.Offset(x0, y1);
  const uint8_t* p11 = data + l.Offset(x1, y1);
  const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
  return {w00 * p00[0] + w01 * p01[0] + w10 * p10[0] + w11 * p11[0],
          w00 * p00[1] + w01 * p01[1] + w10 * p10[1] + w11 * p11[1],
          w00 * p00[2] + w01 * p01[2] + w10 * p10[2] + w11 * p11[2]};
}

inline Eigen::Vector3f MipTexture::Sample(float u, float v, float lod) const {
  if (levels_.empty()) return Eigen::Vector3f::Zero();
  const int last = static_cast<int>(levels_.size()) - 1;
  if (!(lod > 0)) return Bilinear(levels_[0], u, v);
  if (lod >= last) return Bilinear(levels_[last], u, v);
  const int l0 = static_cast<int>(lod);
  const float a = lod - l0;
  if (a < 0.02f) return Bilinear(levels_[l0], u, v);
  if (a > 0.98f) return Bilinear(levels_[l0 + 1], u, v);
  return (1 - a) * Bilinear(levels_[l0], u, v) + a * Bilinear(levels_[l0 + 1], u, v);
}

}  // namespace fmv3d::render
