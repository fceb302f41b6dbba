#include "fmv3d/render/texture.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::render {

MipTexture::MipTexture(const cv::Mat& bgr) {
  if (bgr.empty()) return;
  if (bgr.type() != CV_8UC3) throw Error("texture: expected an 8-bit 3-channel image");
  Level base;
  base.w = bgr.cols;
  base.h = bgr.rows;
  base.bgr.resize(size_t(base.w) * base.h * 3);
  for (int y = 0; y < base.h; ++y) std::copy_n(bgr.ptr<uint8_t>(y), base.w * 3, &base.bgr[size_t(y) * base.w * 3]);
  levels_.push_back(std::move(base));
  while (levels_.back().w > 1 || levels_.back().h > 1) {
    const Level& p = levels_.back();
    Level l;
    l.w = std::max(1, (p.w + 1) / 2);
    l.h = std::max(1, (p.h + 1) / 2);
    l.bgr.resize(size_t(l.w) * l.h * 3);
    for (int y = 0; y < l.h; ++y) {
      const int y0 = std::min(2 * y, p.h - 1), y1 = std::min(2 * y + 1, p.h - 1);
      for (int x = 0; x < l.w; ++x) {
        const int x0 = std::min(2 * x, p.w - 1), x1 = std::min(2 * x + 1, p.w - 1);
        for (int c = 0; c < 3; ++c) {
          const int s = p.bgr[(size_t(y0) * p.w + x0) * 3 + c] + p.bgr[(size_t(y0) * p.w + x1) * 3 + c] +
                        p.bgr[(size_t(y1) * p.w + x0) * 3 + c] + p.bgr[(size_t(y1) * p.w + x1) * 3 + c];
          l.bgr[(size_t(y) * l.w + x) * 3 + c] = static_cast<uint8_t>((s + 2) / 4);
        }
      }
    }
    levels_.push_back(std::move(l));
  }
}

Eigen::Vector3f MipTexture::Bilinear(const Level& l, float u, float v) const {
  // Texel centres at (i + 0.5) / w; v flipped (OBJ convention).
  float x = (u - std::floor(u)) * l.w - 0.5f;
  float y = (1.0f - (v - std::floor(v))) * l.h - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  int x1 = x0 + 1, y1 = y0 + 1;
  // Wrap (textures repeat outside [0, 1]).
  if (x0 < 0) x0 += l.w;
  if (y0 < 0) y0 += l.h;
  if (x1 >= l.w) x1 -= l.w;
  if (y1 >= l.h) y1 -= l.h;
  x0 = std::clamp(x0, 0, l.w - 1);
  y0 = std::clamp(y0, 0, l.h - 1);
  x1 = std::clamp(x1, 0, l.w - 1);
  y1 = std::clamp(y1, 0, l.h - 1);
  const uint8_t* p00 = &l.bgr[(size_t(y0) * l.w + x0) * 3];
  const uint8_t* p01 = &l.bgr[(size_t(y0) * l.w + x1) * 3];
  const uint8_t* p10 = &l.bgr[(size_t(y1) * l.w + x0) * 3];
  const uint8_t* p11 = &l.bgr[(size_t(y1) * l.w + x1) * 3];
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
  if (a < 1e-3f) return Bilinear(levels_[l0], u, v);
  return (1 - a) * Bilinear(levels_[l0], u, v) + a * Bilinear(levels_[l0 + 1], u, v);
}

}  // namespace fmv3d::render
