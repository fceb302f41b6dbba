// Mip-mapped texture with trilinear filtering, for the rasteriser.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

namespace fmv3d::render {

class MipTexture {
 public:
  MipTexture() = default;
  // bgr: CV_8UC3. Builds the pyramid by 2x2 box filtering (odd sizes round up, the last row/column repeat).
  explicit MipTexture(const cv::Mat& bgr);

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
    float fw = 0, fh = 0;
    int tiles_x = 0;
    // 4 bytes per texel (B, G, R, unused), stored in 32x32-texel tiles (4 KiB, one page): a bilinear
    // footprint walking across a large texture in any direction then stays within few pages and cache
    // lines (row-major storage made the shading pass TLB-bound).
    std::vector<uint8_t> bgr;
    size_t Offset(int x, int y) const {
      return ((size_t(y >> 5) * tiles_x + (x >> 5)) << 12) + ((y & 31) << 7) + ((x & 31) << 2);
    }
  };
  Eigen::Vector3f Bilinear(const Level& l, float u, float v) const;
  std::vector<Level> levels_;
};

}  // namespace fmv3d::render
