#include "fmv3d/synth/textures.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fmv3d/synth/noise.h"

namespace fmv3d::synth {
namespace {

using Vec3 = Eigen::Vector3f;  // BGR, 0..255

// Multi-scale noise image (CV_32F, rows × cols, values in [0, 1]) with structure from `largest_px` texels
// down to single texels: a random image is repeatedly enlarged 2× (bicubic) and added to finer random
// detail with weight ×gain per octave (pyramid synthesis, far faster than per-texel fractal noise).
cv::Mat FractalField(int rows, int cols, double largest_px, double gain, uint64_t seed) {
  cv::RNG rng(seed * 2654435761ull + 12345);
  int r = std::max(2, static_cast<int>(std::ceil(rows / largest_px)));
  int c = std::max(2, static_cast<int>(std::ceil(cols / largest_px)));
  cv::Mat f(r, c, CV_32F);
  rng.fill(f, cv::RNG::UNIFORM, -1.0, 1.0);
  float amp = 1.0f;
  while (f.rows < rows || f.cols < cols) {
    const int nr = std::min(rows, f.rows * 2), nc = std::min(cols, f.cols * 2);
    cv::Mat up;
    cv::resize(f, up, cv::Size(nc, nr), 0, 0, cv::INTER_CUBIC);
    amp *= static_cast<float>(gain);
    cv::Mat detail(nr, nc, CV_32F);
    rng.fill(detail, cv::RNG::UNIFORM, -1.0, 1.0);
    f = up + amp * detail;
  }
  cv::normalize(f, f, 0.0, 1.0, cv::NORM_MINMAX);
  return f;
}

inline float Smooth(float e0, float e1, float x) {
  const float t = std::clamp((x - e0) / (e1 - e0), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}
inline Vec3 Mix(const Vec3& a, const Vec3& b, float t) { return a + (b - a) * t; }
inline float White(uint64_t seed, uint64_t i) {
  return static_cast<float>(Hash64(seed ^ Hash64(i)) >> 40) * (1.0f / 16777216.0f) - 0.5f;
}
cv::Vec3b ToPixel(const Vec3& c) {
  return {cv::saturate_cast<uint8_t>(c[0]), cv::saturate_cast<uint8_t>(c[1]), cv::saturate_cast<uint8_t>(c[2])};
}

}  // namespace

cv::Mat GroundTexture(int n, const Eigen::AlignedBox2d& extent, uint64_t seed,
                      const std::function<double(double, double)>& height,
                      const std::function<bool(double, double)>& paved) {
  const double ext = extent.sizes().x();
  const double mpt = ext / n;  // metres per texel
  auto px = [&](double metres) { return metres / mpt; };
  // Smooth fields shared by all land covers.
  const cv::Mat warp_x = FractalField(n, n, px(150), 0.5, seed + 1);
  const cv::Mat warp_y = FractalField(n, n, px(150), 0.5, seed + 2);
  const cv::Mat tone = FractalField(n, n, px(60), 0.62, seed + 3);   // broad colour variation
  const cv::Mat patch = FractalField(n, n, px(8), 0.7, seed + 4);    // bushes, tree crowns, patches
  const cv::Mat grain = FractalField(n, n, px(1.5), 0.8, seed + 5);  // fine grain, down to the texel
  const cv::Mat rock = FractalField(n, n, px(4), 0.75, seed + 6);    // boulders and rock texture
  std::vector<double> road_sin0(n), road_cos0(n);
  for (int col = 0; col < n; ++col) {
    const double x = extent.min().x() + (col + 0.5) * mpt;
    road_sin0[col] = std::sin(x / 90.0 + 1.0);
    road_cos0[col] = std::cos(x / 90.0 + 1.0);
  }
  // Slope (|grad h|) on a coarse grid, interpolated: the height function is far too slow per texel.
  cv::Mat slope_map;
  if (height) {
    const int m = std::max(2, n / 8);
    cv::Mat coarse(m, m, CV_32F);
    const double step = ext / m;
    tbb::parallel_for(0, m, [&](int r) {
      const double y = extent.max().y() - (r + 0.5) * step;
      for (int c = 0; c < m; ++c) {
        const double x = extent.min().x() + (c + 0.5) * step;
        const double hx = height(x + 1, y) - height(x - 1, y), hy = height(x, y + 1) - height(x, y - 1);
        coarse.at<float>(r, c) = static_cast<float>(0.5 * std::sqrt(hx * hx + hy * hy));
      }
    });
    cv::resize(coarse, slope_map, cv::Size(n, n), 0, 0, cv::INTER_LINEAR);
  }
  cv::Mat out(n, n, CV_8UC3);
  tbb::parallel_for(0, n, [&](int row) {
    const double y = extent.max().y() - (row + 0.5) * mpt;
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(row);
    const double road_sin1 = std::sin(y / 110.0), road_cos1 = std::cos(y / 110.0);
    for (int col = 0; col < n; ++col) {
      const double x = extent.min().x() + (col + 0.5) * mpt;
      const float t = tone.at<float>(row, col), p = patch.at<float>(row, col);
      const float g = grain.at<float>(row, col), rk = rock.at<float>(row, col);
      const double wx = x + 60.0 * (warp_x.at<float>(row, col) - 0.5);
      const double wy = y + 60.0 * (warp_y.at<float>(row, col) - 0.5);
      const Cell cell = Voronoi(wx / 55.0, wy / 55.0, seed + 7);
      const double r0 = LatticeRandom(cell.cx, cell.cy, seed + 8);
      const double r1 = LatticeRandom(cell.cx, cell.cy, seed + 9);
      const double r2 = LatticeRandom(cell.cx, cell.cy, seed + 10);
      Vec3 c;
      if (r0 < 0.32) {  // crop field: rows in a per-field direction, two colours
        const double ang = r1 * M_PI, spacing = 0.9 + 1.6 * r2;
        const double s = (x * std::cos(ang) + y * std::sin(ang)) / spacing;  // straight rows
        const float stripe = 0.5f + 0.5f * static_cast<float>(std::sin(2 * M_PI * s));
        const Vec3 crop = r2 < 0.5 ? Vec3(60, 150 + 30 * r1, 120) : Vec3(70, 165, 185 + 30 * r1);
        const Vec3 soil(70, 100, 130);
        c = Mix(soil, crop, 0.35f + 0.65f * stripe * Smooth(0.25f, 0.6f, p + 0.2f));
      } else if (r0 < 0.58) {  // meadow
        c = Mix(Vec3(55, 135, 95), Vec3(85, 170, 150), t);
        c = Mix(c, Vec3(45, 95, 70), Smooth(0.55f, 0.75f, p));
      } else if (r0 < 0.72) {  // bare soil, faint plough lines
        const float plough = 0.5f + 0.5f * static_cast<float>(std::sin(2 * M_PI * (wx * 0.7 + wy * 0.7) / 1.3));
        c = Mix(Vec3(85, 125, 160), Vec3(120, 160, 190), 0.6f * t + 0.25f * plough);
      } else if (r0 < 0.88) {  // forest: crowns as bright blobs with dark gaps
        const float crown = Smooth(0.35f, 0.65f, p);
        c = Mix(Vec3(25, 50, 30), Vec3(50, 115, 75), crown);
        c = Mix(c, Vec3(40, 95, 90), 0.3f * t);
      } else {  // scrub: dry grass with sparse bushes
        c = Mix(Vec3(95, 160, 175), Vec3(120, 180, 195), t);
        c = Mix(c, Vec3(40, 85, 60), Smooth(0.6f, 0.7f, p));
      }
      // Field boundaries: hedges and tracks.
      const double edge = (cell.d2 - cell.d1) * 55.0;  // ~metres from the boundary
      if (edge < 1.6) c = r1 < 0.5 ? Vec3(35, 80, 50) : Vec3(125, 165, 190);
      // Roads: two winding roads and a straight one.
      const double d0 = 40.0 / 90.0 * road_cos0[col], d1 = 35.0 / 110.0 * road_cos1;
      const double road_d[3] = {std::abs(y - (40.0 * road_sin0[col] - 25.0)) / std::sqrt(1.0 + d0 * d0),
                                std::abs(x - (35.0 * road_sin1 + 95.0)) / std::sqrt(1.0 + d1 * d1),
                                std::abs(0.6 * x + 0.8 * y - 160.0)};
      for (int k = 0; k < 3; ++k) {
        const double half = k == 2 ? 2.2 : 3.2;
        if (road_d[k] < half) {
          c = k == 2 ? Mix(Vec3(110, 140, 165), Vec3(130, 160, 180), g) : Mix(Vec3(85, 88, 90), Vec3(110, 112, 115), t);
          if (k < 2 && std::abs(road_d[k] - (half - 0.35)) < 0.08) c = Vec3(215, 215, 215);  // edge line
        } else if (road_d[k] < half + 0.8) {
          c = Mix(c, Vec3(100, 125, 140), 0.6f);  // verge
        }
      }
      if (paved && paved(x, y)) {
        const double jx = x - std::floor(x / 1.2) * 1.2, jy = y - std::floor(y / 1.2) * 1.2;
        const Vec3 tile =
            Vec3(150, 155, 160) *
            (0.9f + 0.2f * static_cast<float>(LatticeRandom(static_cast<int64_t>(std::floor(x / 1.2)),
                                                            static_cast<int64_t>(std::floor(y / 1.2)), seed + 11)));
        c = (jx < 0.06 || jy < 0.06) ? Vec3(105, 110, 115) : tile;
      }
      // Steep slopes turn to rock; boulders everywhere.
      if (!slope_map.empty()) {
        const float slope = slope_map.at<float>(row, col);
        c = Mix(c, Mix(Vec3(105, 115, 125), Vec3(165, 170, 175), rk), Smooth(0.45f, 0.8f, slope));
      }
      if (rk > 0.8f) c = Mix(c, Vec3(150, 160, 170) * (0.6f + 0.6f * rk), Smooth(0.8f, 0.86f, rk));
      // Grain at every scale, then texel-level noise.
      c *= 0.78f + 0.44f * g;
      c += Vec3::Constant(14.0f * White(seed + 12, uint64_t(row) * n + col));
      dst[col] = ToPixel(c);
    }
  });
  return out;
}

cv::Mat LowTextureGround(int n, const Eigen::AlignedBox2d& extent, uint64_t seed) {
  const double mpt = extent.sizes().x() / n;  // metres per texel
  auto px = [&](double metres) { return metres / mpt; };
  const cv::Mat tone = FractalField(n, n, px(80), 0.6, seed + 1);     // broad, slow colour change
  const cv::Mat cover = FractalField(n, n, px(120), 0.55, seed + 2);  // sand / grass / water regions
  const cv::Mat tuft = FractalField(n, n, px(1.2), 0.7, seed + 3);    // grass tufts
  const cv::Mat grain = FractalField(n, n, px(0.6), 0.8, seed + 4);   // sand grain down to the texel
  const cv::Mat warp = FractalField(n, n, px(40), 0.5, seed + 5);     // bends the ripples
  cv::Mat out(n, n, CV_8UC3);
  tbb::parallel_for(0, n, [&](int row) {
    const double y = extent.max().y() - (row + 0.5) * mpt;
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(row);
    for (int col = 0; col < n; ++col) {
      const double x = extent.min().x() + (col + 0.5) * mpt;
      const float t = tone.at<float>(row, col), cv_ = cover.at<float>(row, col);
      const float tf = tuft.at<float>(row, col), g = grain.at<float>(row, col);
      // Wind ripples: ~1.5 m wavelength across the wind (from the north-west), bent by the warp field.
      const double s = (0.8 * x + 0.6 * y + 25.0 * warp.at<float>(row, col)) / 1.5;
      const float ripple = 0.5f + 0.5f * static_cast<float>(std::sin(2 * M_PI * s));
      const Vec3 sand = Mix(Vec3(150, 182, 200), Vec3(158, 190, 207), t) * (0.975f + 0.03f * ripple + 0.03f * g);
      const Vec3 grass = Mix(Vec3(92, 150, 138), Vec3(98, 158, 146), t) * (0.95f + 0.08f * tf);
      const Vec3 water = Mix(Vec3(110, 100, 80), Vec3(114, 104, 84), t);
      Vec3 c = Mix(sand, grass, Smooth(0.5f, 0.62f, cv_));
      c = Mix(c, water, Smooth(0.2f, 0.22f, 0.42f - cv_));  // ponds where the cover field is lowest
      c += Vec3::Constant(3.0f * White(seed + 6, uint64_t(row) * n + col));
      dst[col] = ToPixel(c);
    }
  });
  return out;
}

cv::Mat FacadeTexture(const FacadeSpec& s) {
  double perimeter = 0;
  for (double l : s.wall_lengths) perimeter += l;
  const int cols = std::clamp(static_cast<int>(std::lround(perimeter * s.texels_per_metre)), 16, 4096);
  const int rows = std::clamp(static_cast<int>(std::lround(s.total_height * s.texels_per_metre)), 16, 4096);
  const double mx = perimeter / cols, my = s.total_height / rows;
  const uint64_t seed = s.seed;
  const double rs = LatticeRandom(1, 2, seed), rs2 = LatticeRandom(3, 4, seed);
  const Vec3 wall = rs < 0.33 ? Vec3(150, 185, 205) : rs < 0.66 ? Vec3(75, 95, 160) : Vec3(170, 170, 165);
  const Vec3 frame = rs2 < 0.5 ? Vec3(235, 235, 235) : Vec3(60, 60, 60);
  const cv::Mat stain = FractalField(rows, cols, 5.0 / mx, 0.6, seed + 1);
  const cv::Mat grain = FractalField(rows, cols, 0.5 / mx, 0.8, seed + 2);
  const double bay = 2.6 + 1.2 * rs2, win_w = 0.45 * bay + 0.3, win_h = 1.5;
  cv::Mat out(rows, cols, CV_8UC3);
  tbb::parallel_for(0, rows, [&](int row) {
    const double z = s.total_height - (row + 0.5) * my - s.ground_offset;  // above the ground floor
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(row);
    double wall_start = 0;
    size_t w = 0;
    for (int col = 0; col < cols; ++col) {
      const double u = (col + 0.5) * mx;
      while (w + 1 < s.wall_lengths.size() && u >= wall_start + s.wall_lengths[w]) wall_start += s.wall_lengths[w++];
      const double along = u - wall_start, len = s.wall_lengths[w];
      const float st = stain.at<float>(row, col), gr = grain.at<float>(row, col);
      Vec3 c = wall * (0.8f + 0.35f * st);
      if (z < 0.4) {
        c = Vec3(95, 100, 105) * (0.8f + 0.4f * st);  // plinth
      } else if (z < s.eave_height) {
        const int fl = static_cast<int>(z / s.floor_height);
        const double zf = z - fl * s.floor_height;
        if (zf < 0.18 && fl > 0) c *= 0.8f;  // floor slab
        const int nb = std::max(0, static_cast<int>((len - 1.0) / bay));
        const double margin = (len - nb * bay) / 2;
        const int bi = static_cast<int>(std::floor((along - margin) / bay));
        if (bi >= 0 && bi < nb && z + s.floor_height * 0.1 < s.eave_height) {
          const double lx = along - margin - bi * bay - (bay - win_w) / 2;
          const uint64_t key = (uint64_t(w) * 131 + fl) * 977 + bi;
          const double h0 = LatticeRandom(static_cast<int64_t>(key), 5, seed);
          const double h1 = LatticeRandom(static_cast<int64_t>(key), 6, seed);
          const bool door = fl == 0 && h0 < 0.3;
          const double z0 = door ? 0.05 : 0.9, z1 = door ? 2.4 : 0.9 + win_h;
          if (lx >= 0 && lx <= win_w && zf >= z0 && zf <= z1) {
            const double fx = std::min(lx, win_w - lx), fz = std::min(zf - z0, z1 - zf);
            if (fx < 0.07 || fz < 0.07 || std::abs(lx - win_w / 2) < 0.03) {
              c = frame;
            } else {
              // Glass: a sky reflection gradient that differs per window; some have curtains.
              const float g = static_cast<float>(0.3 * h0 + 0.5 * (lx / win_w) * h1 + 0.3 * (zf - z0) / (z1 - z0));
              c = Mix(Vec3(60, 45, 35), Vec3(190, 170, 150), std::clamp(g, 0.0f, 1.0f));
              if (h1 > 0.6 && zf > z0 + (z1 - z0) * (0.3 + 0.5 * h0))
                c = Mix(Vec3(200, 215, 225), Vec3(120, 150, 190), static_cast<float>(h0));
            }
          } else if (lx >= -0.05 && lx <= win_w + 0.05 && zf < z0 && zf > z0 - 0.12) {
            c = Vec3(200, 200, 200);  // sill
          }
        }
      }
      c *= 0.85f + 0.3f * gr;
      c += Vec3::Constant(12.0f * White(seed + 3, uint64_t(row) * cols + col));
      dst[col] = ToPixel(c);
    }
  });
  return out;
}

cv::Mat RoofTexture(double width_m, double height_m, bool pitched, double tpm, uint64_t seed) {
  const int cols = std::clamp(static_cast<int>(std::lround(width_m * tpm)), 16, 4096);
  const int rows = std::clamp(static_cast<int>(std::lround(height_m * tpm)), 16, 4096);
  const double mx = width_m / cols, my = height_m / rows;
  const cv::Mat dirt = FractalField(rows, cols, 3.0 / mx, 0.65, seed + 1);
  const cv::Mat grain = FractalField(rows, cols, 0.3 / mx, 0.8, seed + 2);
  const double rs = LatticeRandom(7, 8, seed);
  const Vec3 base = pitched ? (rs < 0.5 ? Vec3(45, 70, 150) : Vec3(80, 80, 85)) : Vec3(140, 145, 150);
  cv::Mat out(rows, cols, CV_8UC3);
  tbb::parallel_for(0, rows, [&](int row) {
    const double y = (row + 0.5) * my;
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(row);
    for (int col = 0; col < cols; ++col) {
      const double x = (col + 0.5) * mx;
      const float d = dirt.at<float>(row, col), g = grain.at<float>(row, col);
      Vec3 c = base;
      if (pitched) {
        const double course = 0.33, tile = 0.26;
        const int64_t ci = static_cast<int64_t>(std::floor(y / course));
        const double shift = (ci & 1) ? tile / 2 : 0;
        const int64_t ti = static_cast<int64_t>(std::floor((x + shift) / tile));
        const double fy = y / course - ci, fx = (x + shift) / tile - ti;
        c *= 0.8f + 0.4f * static_cast<float>(LatticeRandom(ti, ci, seed + 3));
        if (fy > 0.85) c *= 0.55f;  // shadow under the next course
        if (fx < 0.05) c *= 0.75f;
        c = Mix(c, Vec3(60, 110, 90), Smooth(0.62f, 0.8f, d) * 0.7f);  // moss
      } else {
        c *= 0.75f + 0.4f * d;
        const double e = std::min({x, y, width_m - x, height_m - y});
        if (e < 0.45) c = Vec3(175, 180, 185) * (e < 0.06 ? 0.6f : 1.0f);  // parapet
        // Roof fixtures (vents, boxes) on a coarse random grid.
        const int64_t bx = static_cast<int64_t>(std::floor(x / 4)), by = static_cast<int64_t>(std::floor(y / 4));
        const double lr = LatticeRandom(bx, by, seed + 4);
        if (lr < 0.25 && e > 1.0) {
          const double fx = x / 4 - bx, fy = y / 4 - by, sz = 0.2 + 0.5 * LatticeRandom(bx, by, seed + 5);
          if (fx > 0.2 && fx < 0.2 + sz && fy > 0.3 && fy < 0.3 + sz * 0.7) {
            const bool rim = fx < 0.24 || fx > 0.16 + sz || fy < 0.34 || fy > 0.26 + sz * 0.7;
            c = rim ? Vec3(70, 70, 75) : Vec3(205, 205, 200) * static_cast<float>(0.85 + 0.3 * lr);
          }
        }
      }
      c *= 0.85f + 0.3f * g;
      c += Vec3::Constant(12.0f * White(seed + 6, uint64_t(row) * cols + col));
      dst[col] = ToPixel(c);
    }
  });
  return out;
}

}  // namespace fmv3d::synth
