#include "fmv3d/render/texture.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::render {

MipTexture::MipTexture(const cv::Mat& bgr, int max_levels) {
  if (max_levels < 1) throw Error("texture: at least one mip level");
  if (bgr.empty()) return;
  if (bgr.type() != CV_8UC3) throw Error("texture: expected an 8-bit 3-channel image");
  cv::Mat level = bgr;
  double span_w = bgr.cols, span_h = bgr.rows;  // texels of this level across u, v ∈ [0, 1]
  while (true) {
    Level l;
    l.w = level.cols;
    l.h = level.rows;
    // Not the texel count: after an odd size the last texel is a repeat that lies past u = 1, and texel x of
    // every level must stay centred on the texels it averages — (x + 0.5) / span in u. Using the rounded count
    // stretched coarse levels (3380 → … → 845 → 423 texels: 0.12%, then 0.24% more), so the ground slid
    // against the geometry with distance and resolution: 640x360 orbits came out 0.16% elliptical.
    l.fw = static_cast<float>(span_w);
    l.fh = static_cast<float>(span_h);
    l.tiles_x = (l.w + 31) / 32;
    l.bgr = cv::Mat::zeros((l.h + 31) / 32, l.tiles_x * 4096, CV_8U);  // a matrix row per row of tiles
    uint8_t* const data = l.bgr.data;
    for (int y = 0; y < l.h; ++y) {
      const uint8_t* src = level.ptr<uint8_t>(y);
      for (int x = 0; x < l.w; ++x, src += 3) {
        uint8_t* dst = data + l.Offset(x, y);
        dst[0] = src[0];
        dst[1] = src[1];
        dst[2] = src[2];
      }
    }
    levels_.push_back(std::move(l));
    if ((level.cols == 1 && level.rows == 1) || static_cast<int>(levels_.size()) == max_levels) break;
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
          dst[3 * x + c] =
              static_cast<uint8_t>((r0[3 * x0 + c] + r0[3 * x1 + c] + r1[3 * x0 + c] + r1[3 * x1 + c] + 2) / 4);
      }
    }
    level = next;
    span_w /= 2, span_h /= 2;
  }
}

}  // namespace fmv3d::render
