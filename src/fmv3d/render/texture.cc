#include "fmv3d/render/texture.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::render {

MipTexture::MipTexture(const cv::Mat& bgr) {
  if (bgr.empty()) return;
  if (bgr.type() != CV_8UC3) throw Error("texture: expected an 8-bit 3-channel image");
  cv::Mat level = bgr;
  while (true) {
    Level l;
    l.w = level.cols;
    l.h = level.rows;
    l.fw = static_cast<float>(l.w);
    l.fh = static_cast<float>(l.h);
    l.tiles_x = (l.w + 31) / 32;
    l.bgr.assign(size_t(l.tiles_x) * ((l.h + 31) / 32) * 4096, 0);
    for (int y = 0; y < l.h; ++y) {
      const uint8_t* src = level.ptr<uint8_t>(y);
      for (int x = 0; x < l.w; ++x) {
        uint8_t* dst = &l.bgr[l.Offset(x, y)];
        dst[0] = src[3 * x];
        dst[1] = src[3 * x + 1];
        dst[2] = src[3 * x + 2];
      }
    }
    levels_.push_back(std::move(l));
    if (level.cols == 1 && level.rows == 1) break;
    // 2×2 box filter; odd sizes round up and repeat the last row/column.
    const int w = std::max(1, (level.cols + 1) / 2), h = std::max(1, (level.rows + 1) / 2);
    cv::Mat next(h, w, CV_8UC3);
    for (int y = 0; y < h; ++y) {
      const int y0 = std::min(2 * y, level.rows - 1), y1 = std::min(2 * y + 1, level.rows - 1);
      const uint8_t* r0 = level.ptr<uint8_t>(y0);
      const uint8_t* r1 = level.ptr<uint8_t>(y1);
      uint8_t* dst = next.ptr<uint8_t>(y);
      for (int x = 0; x < w; ++x) {
        const int x0 = std::min(2 * x, level.cols - 1), x1 = std::min(2 * x + 1, level.cols - 1);
        for (int c = 0; c < 3; ++c)
          dst[3 * x + c] = static_cast<uint8_t>((r0[3 * x0 + c] + r0[3 * x1 + c] + r1[3 * x0 + c] + r1[3 * x1 + c] + 2) / 4);
      }
    }
    level = next;
  }
}

Eigen::Vector3f MipTexture::Bilinear(const Level& l, float u, float v) const {
  // Texel centres at (i + 0.5) / w; v flipped (OBJ convention); coordinates wrap.
  const float x = u * l.fw - 0.5f, y = (1.0f - v) * l.fh - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (x0 < 0 || x0 >= l.w) x0 = ((x0 % l.w) + l.w) % l.w;
  if (y0 < 0 || y0 >= l.h) y0 = ((y0 % l.h) + l.h) % l.h;
  const int x1 = x0 + 1 < l.w ? x0 + 1 : 0, y1 = y0 + 1 < l.h ? y0 + 1 : 0;
  const uint8_t* p00 = &l.bgr[l.Offset(x0, y0)];
  const uint8_t* p01 = &l.bgr[l.Offset(x1, y0)];
  const uint8_t* p10 = &l.bgr[l.Offset(x0, y1)];
  const uint8_t* p11 = &l.bgr[l.Offset(x1, y1)];
  const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
  return {w00 * p00[0] + w01 * p01[0] + w10 * p10[0] + w11 * p11[0],
          w00 * p00[1] + w01 * p01[1] + w10 * p10[1] + w11 * p11[1],
          w00 * p00[2] + w01 * p01[2] + w10 * p10[2] + w11 * p11[2]};
}

Eigen::Vector3f MipTexture::Sample(float u, float v, float lod) const {
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
