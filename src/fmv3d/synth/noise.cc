#include "fmv3d/synth/noise.h"

#include <cmath>

namespace fmv3d::synth {

uint64_t Hash64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

double LatticeRandom(int64_t x, int64_t y, uint64_t seed) {
  const uint64_t h = Hash64(static_cast<uint64_t>(x) * 0x8CB92BA72F3D8DD7ull ^
                            Hash64(static_cast<uint64_t>(y) + seed * 0x9E3779B97F4A7C15ull));
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

namespace {
inline double Fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
}  // namespace

double ValueNoise(double x, double y, uint64_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const int64_t ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy);
  const double tx = Fade(x - fx), ty = Fade(y - fy);
  const double a = LatticeRandom(ix, iy, seed), b = LatticeRandom(ix + 1, iy, seed);
  const double c = LatticeRandom(ix, iy + 1, seed), d = LatticeRandom(ix + 1, iy + 1, seed);
  return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty;
}

double Fbm(double x, double y, uint64_t seed, int octaves, double gain) {
  double sum = 0, amp = 1, norm = 0;
  for (int o = 0; o < octaves; ++o) {
    // Rotate each octave a little so lattice artefacts do not line up.
    const double c = 0.8, s = 0.6;
    sum += amp * ValueNoise(x, y, seed + 7919 * o);
    norm += amp;
    const double nx = 2.0 * (c * x - s * y) + 17.3, ny = 2.0 * (s * x + c * y) - 5.1;
    x = nx;
    y = ny;
    amp *= gain;
  }
  return sum / norm;
}

double RidgedFbm(double x, double y, uint64_t seed, int octaves) {
  double sum = 0, amp = 1, norm = 0;
  for (int o = 0; o < octaves; ++o) {
    const double n = 1.0 - std::abs(2.0 * ValueNoise(x, y, seed + 104729 * o) - 1.0);
    sum += amp * n * n;
    norm += amp;
    const double nx = 2.0 * (0.8 * x - 0.6 * y) + 3.7, ny = 2.0 * (0.6 * x + 0.8 * y) + 11.9;
    x = nx;
    y = ny;
    amp *= 0.5;
  }
  return sum / norm;
}

Cell Voronoi(double x, double y, uint64_t seed) {
  const int64_t ix = static_cast<int64_t>(std::floor(x)), iy = static_cast<int64_t>(std::floor(y));
  Cell best;
  best.d1 = best.d2 = 1e30;
  for (int64_t j = iy - 1; j <= iy + 1; ++j)
    for (int64_t i = ix - 1; i <= ix + 1; ++i) {
      const double px = i + 0.1 + 0.8 * LatticeRandom(i, j, seed);
      const double py = j + 0.1 + 0.8 * LatticeRandom(i, j, seed + 1);
      const double d = std::hypot(px - x, py - y);
      if (d < best.d1) {
        best.d2 = best.d1;
        best.d1 = d;
        best.cx = i;
        best.cy = j;
      } else if (d < best.d2) {
        best.d2 = d;
      }
    }
  return best;
}

}  // namespace fmv3d::synth
