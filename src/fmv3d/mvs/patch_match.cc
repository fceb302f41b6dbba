// One file (~600 lines) by design: the Solver's sampling, NCC cost, propagation and refinement share its per-level
// state and SIMD vector types in one hot loop; split across files they would have to expose the kernel's internals
// in a header. The public interface is patch_match.h.
#include "fmv3d/mvs/patch_match.h"

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#ifdef __SSE2__
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define FMV3D_PM_AVX2 1
#endif
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <limits>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"

namespace fmv3d::mvs {
// #define PM_COUNT  // uncomment for hypothesis counters on stderr (development only)
#ifdef PM_COUNT
std::atomic<long> g_cost_calls{0}, g_ncc_calls{0}, g_pruned{0}, g_trials{0}, g_dedup{0}, g_accept{0}, g_skip{0};
#define PMC(x) (x)++
#else
#define PMC(x) (void)0
#endif
namespace {

constexpr float kMaxCost = 2.0f;
// A source that cannot see the whole patch (outside its image or behind it) says nothing about the plane: it
// costs what uncorrelated patches cost (NCC 0). The worst cost instead made every pixel that fewer than top_k
// sources see fail, whatever its match in the sources that do: most of a grid survey's surface.
constexpr float kNoViewCost = 1.0f;
constexpr int kMaxSamples = 64;  // (2·radius/step + 1)² for the allowed options, rounded up to kLanes
constexpr int kLanes = 4;        // the NCC works on groups of 4 samples (SSE2 width; GCC/Clang vector types)
using V4f = float __attribute__((vector_size(16)));
using V4i = int __attribute__((vector_size(16)));
inline V4f Load4(const float* p) {
  V4f v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}
inline V4f Splat(float f) { return V4f{f, f, f, f}; }
inline float Sum4(V4f v) { return (v[0] + v[1]) + (v[2] + v[3]); }

// The 3 × 3 algebra of the cost, written out on the coefficients: clang's sanitizer build leaves Eigen's
// expression templates there as out-of-line calls (a quarter of the dense tests' time under ASan). Each sum keeps
// the order of Eigen's unrolled reduction, a0 + (a1 + a2), so results are bit-identical to the Eigen form.
inline Eigen::Vector3f Mul(const Eigen::Matrix3f& M, const Eigen::Vector3f& v) {
  const float* m = M.data();  // column-major
  const float x = v[0], y = v[1], z = v[2];
  return {m[0] * x + (m[3] * y + m[6] * z), m[1] * x + (m[4] * y + m[7] * z), m[2] * x + (m[5] * y + m[8] * z)};
}
// Mᵀ v
inline Eigen::Vector3f MulTransposed(const Eigen::Matrix3f& M, const Eigen::Vector3f& v) {
  const float* m = M.data();
  const float x = v[0], y = v[1], z = v[2];
  return {m[0] * x + (m[1] * y + m[2] * z), m[3] * x + (m[4] * y + m[5] * z), m[6] * x + (m[7] * y + m[8] * z)};
}
inline float Dot(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return a[0] * b[0] + (a[1] * b[1] + a[2] * b[2]);
}

// Counter-based random numbers: a pixel's draws depend only on (seed, pixel, round), so results do not depend
// on thread scheduling.
struct Rng {
  uint64_t s;
  explicit Rng(uint64_t seed) : s(seed) {}
  uint64_t Next() {
    uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float Uniform() { return static_cast<float>(Next() >> 40) * (1.0f / 16777216.0f); }  // [0, 1)
  float Symmetric() { return 2 * Uniform() - 1; }                                      // [-1, 1)
};

struct Source {
  const float* img = nullptr;
  int w = 0, h = 0;
  size_t stride = 0;  // floats per row
  Eigen::Matrix3f K;
  Eigen::Matrix3f R;  // reference camera frame → source camera frame
  Eigen::Vector3f t;
  // Plane-induced homography ref pixels → source pixels for the plane n·X + c = 0 (X in the reference frame):
  // H = K_s (R − t nᵀ/c) K⁻¹ = A + b · (nᵀ K⁻¹ / (−c)); A and b are fixed per level.
  Eigen::Matrix3f A;
  Eigen::Vector3f b;
  const DepthMap* map = nullptr;    // geometric pass only (at the source's working resolution)
  Eigen::Matrix3f map_K, map_Kinv;  // intrinsics of that map
};

// One resolution level of the problem.
struct Level {
  cv::Mat ref;  // CV_32F grey
  int w = 0, h = 0;
  Eigen::Matrix3f K, Kinv;
  std::vector<cv::Mat> images;  // owned source images (resized)
  std::vector<Source> sources;
};

// The reference side of the NCC, once per pixel update: bilateral weights w (normalised to sum 1) and
// wr = w·(v − mean)/σ, so that NCC = Σ wr·s / σ_s for source samples s. Padding lanes have w = wr = 0.
struct RefPatch {
  alignas(32) float w[kMaxSamples];
  alignas(32) float wr[kMaxSamples];
};

class Solver {
 public:
  Solver(const Level& level, const PatchMatchOptions& opt, double dmin, double dmax, uint64_t seed)
      : L_(level), opt_(opt), dmin_(static_cast<float>(dmin)), dmax_(static_cast<float>(dmax)), seed_(seed) {
    side_ = 2 * (opt.window_radius / opt.window_step) + 1;
    n_samples_ = side_ * side_;
    const int r = (side_ / 2) * opt.window_step;
    radius_ = r;
    spatial_.resize(n_samples_);
    for (int j = 0; j < side_; ++j)
      for (int i = 0; i < side_; ++i) {
        const float dx = static_cast<float>(-r + i * opt.window_step),
                    dy = static_cast<float>(-r + j * opt.window_step);
        spatial_[j * side_ + i] = -(dx * dx + dy * dy) / static_cast<float>(2 * opt.sigma_spatial * opt.sigma_spatial);
      }
    inv_2sc2_ = static_cast<float>(1.0 / (2 * opt.sigma_color * opt.sigma_color));
    // Sample offsets from the patch's top-left sample, padded to whole groups of the kernel's lanes with copies of
    // the first sample (weight 0).
    use_avx2_ = opt.use_avx2 && Avx2KernelAvailable();
    const int group = use_avx2_ ? 2 * kLanes : kLanes;
    n_padded_ = (n_samples_ + group - 1) / group * group;
    for (int k = 0; k < kMaxSamples; ++k) {
      const int kk = k < n_samples_ ? k : 0;
      const int row = kk / side_, col = kk % side_;  // the window's sample grid, row-major
      off_x_[k] = static_cast<float>(col * opt.window_step);
      off_y_[k] = static_cast<float>(row * opt.window_step);
    }
    const size_t n = static_cast<size_t>(L_.w) * L_.h;
    depth_.assign(n, 0);
    normal_.assign(n, Eigen::Vector3f(0, 0, -1));
    cost_.assign(n, kMaxCost);
    photo_.assign(n, kMaxCost);
    changed_.assign(n, 0);
    updated_.assign(n, 0);
  }

  std::vector<float> depth_, cost_, photo_;
  std::vector<Eigen::Vector3f> normal_;

  Eigen::Vector3f Ray(int x, int y) const {
    return Mul(L_.Kinv, Eigen::Vector3f(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f, 1.f));
  }

  Eigen::Vector3f RandomNormal(Rng& rng, const Eigen::Vector3f& ray) const {
    const Eigen::Vector3f dir = ray.normalized();
    for (int tries = 0; tries < 16; ++tries) {
      Eigen::Vector3f n(rng.Symmetric(), rng.Symmetric(), rng.Symmetric());
      const float len = n.norm();
      if (len > 1 || len < 1e-3f) continue;
      n /= len;
      float c = n.dot(dir);
      if (c > 0) n = -n, c = -c;
      if (c < -0.1f) return n;  // not grazing
    }
    return -dir;
  }

  // Uniform in inverse depth (disparity): equal steps of parallax, so a range that reaches far surfaces
  // does not spend its samples there.
  float RandomDepth(Rng& rng) const {
    const float inv_far = 1.0f / dmax_, inv_near = 1.0f / dmin_;
    return 1.0f / (inv_far + rng.Uniform() * (inv_near - inv_far));
  }

  void ComputeRefPatch(int x, int y, RefPatch* p) const {
    const float* img = L_.ref.ptr<float>(0);
    const size_t stride = L_.ref.step1();
    const float centre = img[y * stride + x];
    float v[kMaxSamples];
    float sum_w = 0;
    for (int j = 0, k = 0; j < side_; ++j) {
      const int yy = std::clamp(y - radius_ + j * opt_.window_step, 0, L_.h - 1);
      for (int i = 0; i < side_; ++i, ++k) {
        const int xx = std::clamp(x - radius_ + i * opt_.window_step, 0, L_.w - 1);
        v[k] = img[yy * stride + xx];
        const float d = v[k] - centre;
        const float w = std::exp(spatial_[k] - d * d * inv_2sc2_);
        p->w[k] = w;
        sum_w += w;
      }
    }
    float mean = 0, sq = 0;
    for (int k = 0; k < n_samples_; ++k) {
      p->w[k] /= sum_w;
      mean += p->w[k] * v[k];
      sq += p->w[k] * v[k] * v[k];
    }
    constexpr float kEps = 1e-6f;
    const float inv_sigma = 1.f / std::sqrt(std::max(sq - mean * mean, kEps));
    for (int k = 0; k < n_samples_; ++k) p->wr[k] = p->w[k] * (v[k] - mean) * inv_sigma;
    for (int k = n_samples_; k < n_padded_; ++k) p->w[k] = p->wr[k] = 0;
  }

  // 1 − weighted NCC of the reference patch against source s through homography H; kNoViewCost when a sample
  // falls outside the source image (or behind it). All sample positions are computed first, 4 at a time,
  // directly from H (no incremental drift), and bounds-tested together; then the bilinear samples are gathered
  // and accumulated 4 lanes at a time.
  float Ncc(const RefPatch& rp, int x, int y, const Eigen::Matrix3f& H, const Source& s) const {
    const float u0 = static_cast<float>(x - radius_) + 0.5f, v0 = static_cast<float>(y - radius_) + 0.5f;
    const Eigen::Vector3f o = Mul(H, Eigen::Vector3f(u0, v0, 1.f));
    const V4f ox = Splat(o.x() - 0.5f * o.z()), oy = Splat(o.y() - 0.5f * o.z()), oz = Splat(o.z());
    const V4f hx0 = Splat(H(0, 0) - 0.5f * H(2, 0)), hy0 = Splat(H(1, 0) - 0.5f * H(2, 0)), hz0 = Splat(H(2, 0));
    const V4f hx1 = Splat(H(0, 1) - 0.5f * H(2, 1)), hy1 = Splat(H(1, 1) - 0.5f * H(2, 1)), hz1 = Splat(H(2, 1));
    const V4f wmax = Splat(static_cast<float>(s.w - 1)), hmax = Splat(static_cast<float>(s.h - 1));
    const V4f zero = Splat(0.f);
    alignas(16) float fx[kMaxSamples], fy[kMaxSamples];
    V4i ok = {-1, -1, -1, -1};
    for (int k = 0; k < n_padded_; k += kLanes) {
      const V4f dx = Load4(&off_x_[k]), dy = Load4(&off_y_[k]);
      const V4f z = oz + dx * hz0 + dy * hz1;
      // Pixel centres at +0.5: fx = u/z − 0.5 = (u − 0.5 z)/z, folded into the rows above.
      const V4f iz = 1.f / z;
      const V4f px = (ox + dx * hx0 + dy * hx1) * iz, py = (oy + dx * hy0 + dy * hy1) * iz;
      ok &= (z > zero) & (px >= zero) & (py >= zero) & (px < wmax) & (py < hmax);  // false for NaN too
      __builtin_memcpy(&fx[k], &px, sizeof px);
      __builtin_memcpy(&fy[k], &py, sizeof py);
    }
    if (!(ok[0] & ok[1] & ok[2] & ok[3])) return kNoViewCost;
    V4f acc_s = zero, acc_ss = zero, acc_rs = zero;
    const size_t st = s.stride;
    for (int k = 0; k < n_padded_; k += kLanes) {
      const V4f px = Load4(&fx[k]), py = Load4(&fy[k]);
      const V4i ix = __builtin_convertvector(px, V4i), iy = __builtin_convertvector(py, V4i);  // >= 0: floor
      const V4f ax = px - __builtin_convertvector(ix, V4f), ay = py - __builtin_convertvector(iy, V4f);
      V4f t0, t1, b0, b1;
#ifdef __SSE2__
      // Each lane's two horizontal neighbours are adjacent floats: one 64-bit load per row and lane, then a
      // transpose (8 loads + 4 shuffles instead of 16 scalar loads and inserts).
      const float* r0 = s.img + static_cast<size_t>(iy[0]) * st + static_cast<size_t>(ix[0]);
      const float* r1 = s.img + static_cast<size_t>(iy[1]) * st + static_cast<size_t>(ix[1]);
      const float* r2 = s.img + static_cast<size_t>(iy[2]) * st + static_cast<size_t>(ix[2]);
      const float* r3 = s.img + static_cast<size_t>(iy[3]) * st + static_cast<size_t>(ix[3]);
      const __m128 z = _mm_setzero_ps();
      const __m128 top01 =
          _mm_loadh_pi(_mm_loadl_pi(z, reinterpret_cast<const __m64*>(r0)), reinterpret_cast<const __m64*>(r1));
      const __m128 top23 =
          _mm_loadh_pi(_mm_loadl_pi(z, reinterpret_cast<const __m64*>(r2)), reinterpret_cast<const __m64*>(r3));
      const __m128 bot01 = _mm_loadh_pi(_mm_loadl_pi(z, reinterpret_cast<const __m64*>(r0 + st)),
                                        reinterpret_cast<const __m64*>(r1 + st));
      const __m128 bot23 = _mm_loadh_pi(_mm_loadl_pi(z, reinterpret_cast<const __m64*>(r2 + st)),
                                        reinterpret_cast<const __m64*>(r3 + st));
      t0 = reinterpret_cast<V4f>(_mm_shuffle_ps(top01, top23, _MM_SHUFFLE(2, 0, 2, 0)));
      t1 = reinterpret_cast<V4f>(_mm_shuffle_ps(top01, top23, _MM_SHUFFLE(3, 1, 3, 1)));
      b0 = reinterpret_cast<V4f>(_mm_shuffle_ps(bot01, bot23, _MM_SHUFFLE(2, 0, 2, 0)));
      b1 = reinterpret_cast<V4f>(_mm_shuffle_ps(bot01, bot23, _MM_SHUFFLE(3, 1, 3, 1)));
#else
      for (int l = 0; l < kLanes; ++l) {
        const float* r = s.img + static_cast<size_t>(iy[l]) * st + static_cast<size_t>(ix[l]);
        t0[l] = r[0];
        t1[l] = r[1];
        b0[l] = r[st];
        b1[l] = r[st + 1];
      }
#endif
      const V4f top = t0 + ax * (t1 - t0), bot = b0 + ax * (b1 - b0);
      const V4f v = top + ay * (bot - top);
      const V4f wv = Load4(&rp.w[k]) * v;
      acc_s += wv;
      acc_ss += wv * v;
      acc_rs += Load4(&rp.wr[k]) * v;
    }
    const float sw_s = Sum4(acc_s);
    const float var_s = std::max(Sum4(acc_ss) - sw_s * sw_s, 0.f);
    constexpr float kEps = 1e-6f;
    const float ncc = Sum4(acc_rs) / std::sqrt(std::max(var_s, kEps));
    return std::clamp(1.f - ncc, 0.f, kMaxCost);
  }

#ifdef FMV3D_PM_AVX2
  // Ncc on 8 lanes: the same samples, positions and bilinear interpolation (25 samples padded to 32 with weight 0;
  // a 4-lane tail for the last group measured no faster). Compiled for AVX2 and FMA whatever the build's target
  // and used only on CPUs that have them. The sums are grouped differently, so costs differ from Ncc's in the last
  // bits.
  __attribute__((target("avx2,fma"), noinline)) float NccAvx2(const RefPatch& rp, int x, int y,
                                                              const Eigen::Matrix3f& H, const Source& s) const {
    const float u0 = static_cast<float>(x - radius_) + 0.5f, v0 = static_cast<float>(y - radius_) + 0.5f;
    const float* h = H.data();  // column-major
    const float oz = h[2] * u0 + (h[5] * v0 + h[8]);
    const float ox = h[0] * u0 + (h[3] * v0 + h[6]) - 0.5f * oz, oy = h[1] * u0 + (h[4] * v0 + h[7]) - 0.5f * oz;
    // Pixel centres at +0.5: fx = u/z − 0.5 = (u − 0.5 z)/z, folded into the rows.
    const float hx0 = h[0] - 0.5f * h[2], hy0 = h[1] - 0.5f * h[2], hx1 = h[3] - 0.5f * h[5], hy1 = h[4] - 0.5f * h[5];
    alignas(32) float fx[kMaxSamples], fy[kMaxSamples];
    {
      const __m256 Ox = _mm256_set1_ps(ox), Oy = _mm256_set1_ps(oy), Oz = _mm256_set1_ps(oz);
      const __m256 Hx0 = _mm256_set1_ps(hx0), Hy0 = _mm256_set1_ps(hy0), Hz0 = _mm256_set1_ps(h[2]);
      const __m256 Hx1 = _mm256_set1_ps(hx1), Hy1 = _mm256_set1_ps(hy1), Hz1 = _mm256_set1_ps(h[5]);
      const __m256 wmax = _mm256_set1_ps(static_cast<float>(s.w - 1)),
                   hmax = _mm256_set1_ps(static_cast<float>(s.h - 1)), zero = _mm256_setzero_ps();
      __m256 ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
      for (int k = 0; k < n_padded_; k += 8) {
        const __m256 dx = _mm256_load_ps(&off_x_[k]), dy = _mm256_load_ps(&off_y_[k]);
        const __m256 z = _mm256_fmadd_ps(dy, Hz1, _mm256_fmadd_ps(dx, Hz0, Oz));
        const __m256 px = _mm256_div_ps(_mm256_fmadd_ps(dy, Hx1, _mm256_fmadd_ps(dx, Hx0, Ox)), z);
        const __m256 py = _mm256_div_ps(_mm256_fmadd_ps(dy, Hy1, _mm256_fmadd_ps(dx, Hy0, Oy)), z);
        // Ordered comparisons: false for NaN.
        const __m256 in = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps(z, zero, _CMP_GT_OQ),
                          _mm256_and_ps(_mm256_cmp_ps(px, zero, _CMP_GE_OQ), _mm256_cmp_ps(py, zero, _CMP_GE_OQ))),
            _mm256_and_ps(_mm256_cmp_ps(px, wmax, _CMP_LT_OQ), _mm256_cmp_ps(py, hmax, _CMP_LT_OQ)));
        ok = _mm256_and_ps(ok, in);
        _mm256_store_ps(&fx[k], px);
        _mm256_store_ps(&fy[k], py);
      }
      if (_mm256_movemask_ps(ok) != 0xff) return kNoViewCost;
    }
    const float* row0 = s.img;
    const float* row1 = s.img + s.stride;
    const int stride = static_cast<int>(s.stride);
    // Each lane's two horizontal neighbours are adjacent floats: one 64-bit load per row and lane (faster than
    // AVX2's gathers on the CPUs measured), then a transpose.
    auto pair = [](const float* row, int a, int b) {
      return _mm_loadh_pi(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(row + a)),
                          reinterpret_cast<const __m64*>(row + b));
    };
    __m256 acc_s = _mm256_setzero_ps(), acc_ss = acc_s, acc_rs = acc_s;
    for (int k = 0; k < n_padded_; k += 8) {
      const __m256 px = _mm256_load_ps(&fx[k]), py = _mm256_load_ps(&fy[k]);
      const __m256i ix = _mm256_cvttps_epi32(px), iy = _mm256_cvttps_epi32(py);  // >= 0: floor
      const __m256 ax = _mm256_sub_ps(px, _mm256_cvtepi32_ps(ix)), ay = _mm256_sub_ps(py, _mm256_cvtepi32_ps(iy));
      alignas(32) int at[8];
      _mm256_store_si256(reinterpret_cast<__m256i*>(at),
                         _mm256_add_epi32(_mm256_mullo_epi32(iy, _mm256_set1_epi32(stride)), ix));
      const __m256 top01 = _mm256_set_m128(pair(row0, at[4], at[5]), pair(row0, at[0], at[1]));
      const __m256 top23 = _mm256_set_m128(pair(row0, at[6], at[7]), pair(row0, at[2], at[3]));
      const __m256 bot01 = _mm256_set_m128(pair(row1, at[4], at[5]), pair(row1, at[0], at[1]));
      const __m256 bot23 = _mm256_set_m128(pair(row1, at[6], at[7]), pair(row1, at[2], at[3]));
      const __m256 t0 = _mm256_shuffle_ps(top01, top23, _MM_SHUFFLE(2, 0, 2, 0));
      const __m256 t1 = _mm256_shuffle_ps(top01, top23, _MM_SHUFFLE(3, 1, 3, 1));
      const __m256 b0 = _mm256_shuffle_ps(bot01, bot23, _MM_SHUFFLE(2, 0, 2, 0));
      const __m256 b1 = _mm256_shuffle_ps(bot01, bot23, _MM_SHUFFLE(3, 1, 3, 1));
      const __m256 top = _mm256_fmadd_ps(ax, _mm256_sub_ps(t1, t0), t0);
      const __m256 bot = _mm256_fmadd_ps(ax, _mm256_sub_ps(b1, b0), b0);
      const __m256 v = _mm256_fmadd_ps(ay, _mm256_sub_ps(bot, top), top);
      const __m256 wv = _mm256_mul_ps(_mm256_load_ps(&rp.w[k]), v);
      acc_s = _mm256_add_ps(acc_s, wv);
      acc_ss = _mm256_fmadd_ps(wv, v, acc_ss);
      acc_rs = _mm256_fmadd_ps(_mm256_load_ps(&rp.wr[k]), v, acc_rs);
    }
    const __m128 s4 = _mm_add_ps(_mm256_castps256_ps128(acc_s), _mm256_extractf128_ps(acc_s, 1));
    const __m128 ss4 = _mm_add_ps(_mm256_castps256_ps128(acc_ss), _mm256_extractf128_ps(acc_ss, 1));
    const __m128 rs4 = _mm_add_ps(_mm256_castps256_ps128(acc_rs), _mm256_extractf128_ps(acc_rs, 1));
    const float sw_s = Sum4(s4);
    const float var_s = std::max(Sum4(ss4) - sw_s * sw_s, 0.f);
    constexpr float kEps = 1e-6f;
    const float ncc = Sum4(rs4) / std::sqrt(std::max(var_s, kEps));
    return std::clamp(1.f - ncc, 0.f, kMaxCost);
  }
#endif

  // Forward–backward reprojection error (pixels) of the reference point X through source s's depth map.
  float ReprojectionError(int x, int y, const Eigen::Vector3f& X, const Source& s) const {
    const float maxe = static_cast<float>(opt_.geom_max_error_px);
    const Eigen::Vector3f xs = Mul(s.R, X) + s.t;
    if (!(xs.z() > 0)) return maxe;
    const Eigen::Vector3f q = Mul(s.map_K, xs);
    const float qx = q.x() / q.z(), qy = q.y() / q.z();
    const int ix = static_cast<int>(std::floor(qx)), iy = static_cast<int>(std::floor(qy));
    if (ix < 0 || iy < 0 || ix >= s.map->width() || iy >= s.map->height()) return maxe;
    const float zs = s.map->depth.at<float>(iy, ix);
    if (!(zs > 0)) return maxe;
    // (zs K⁻¹) q, as Eigen evaluates zs (K⁻¹ q).
    const Eigen::Vector3f xs2 = Mul(zs * s.map_Kinv, Eigen::Vector3f(qx, qy, 1.f));
    const Eigen::Vector3f xr = MulTransposed(s.R, xs2 - s.t);
    if (!(xr.z() > 0)) return maxe;
    const Eigen::Vector3f pr = Mul(L_.K, xr);
    const float ex = pr.x() / pr.z() - (static_cast<float>(x) + 0.5f);
    const float ey = pr.y() / pr.z() - (static_cast<float>(y) + 0.5f);
    return std::min(std::sqrt(ex * ex + ey * ey), maxe);
  }

  // False when the k smallest of totals[0..ns) cannot average `bound` or more: k totals of the sources from
  // `scored` on (still at their lower bounds) sum, with a margin for rounding, below k · bound. Saves the sort in
  // most tests; when it returns true the exact test decides.
  static bool MayReach(const float* totals, int scored, int ns, int k, float bound) {
    if (ns - scored < k) return true;
    float sum = 0;
    for (int j = scored; j < scored + k; ++j) sum += totals[j];
    return !(sum < 0.9999f * static_cast<float>(k) * bound);
  }

  // Aggregated cost of plane (depth d, normal n) at pixel (x, y); *photo gets the photometric part.
  // Early termination: the result only matters when it is below `bound` (the pixel's best so far). After each
  // source, the mean of the k smallest of {totals so far} ∪ {lower bounds of the sources not yet scored} is a
  // lower bound of the final top-k mean (photometric costs are >= 0; the geometric term is known before any
  // NCC); once it reaches `bound` the plane is rejected without scoring the other sources. The returned value
  // is then >= bound (not the exact cost), so callers that keep only costs < bound get identical results.
  float Cost(const RefPatch& rp, int x, int y, float d, const Eigen::Vector3f& n, float* photo,
             float bound = std::numeric_limits<float>::infinity()) const {
    *photo = kMaxCost;
    PMC(g_cost_calls);
    if (!(d >= dmin_ && d <= dmax_)) return kMaxCost + 1;
    const Eigen::Vector3f X = d * Ray(x, y);
    const float c = Dot(n, X);
    if (!(c < 0)) return kMaxCost + 1;                            // plane seen from behind
    const Eigen::Vector3f nKinv = MulTransposed(L_.Kinv, n) / c;  // (nᵀ K⁻¹ / c)ᵀ
    float costs[16], totals[16];
    const int ns = static_cast<int>(std::min<size_t>(L_.sources.size(), 16));
    const int k = std::max(1, std::min(opt_.top_k, ns));
    // totals[] holds each source's lower bound until it is scored.
    for (int i = 0; i < ns; ++i) {
      const Source& s = L_.sources[i];
      totals[i] = s.map ? static_cast<float>(opt_.geom_weight) * ReprojectionError(x, y, X, s) : 0.f;
    }
    // Sum of the k smallest totals, in ascending order (order[] gets their indices); insertion sort, ns <= 16.
    auto k_smallest_sum = [&](int* order) {
      for (int i = 0; i < ns; ++i) {
        int j = i;
        for (; j > 0 && totals[order[j - 1]] > totals[i]; --j) order[j] = order[j - 1];
        order[j] = i;
      }
      float sum = 0;
      for (int i = 0; i < k; ++i) sum += totals[order[i]];
      return sum;
    };
    int order[16];
    for (int i = 0; i < ns; ++i) {
      const Source& s = L_.sources[i];
      Eigen::Matrix3f H;  // A + b nKinvᵀ
      for (int col = 0; col < 3; ++col)
        for (int row = 0; row < 3; ++row) H.data()[3 * col + row] = s.A.data()[3 * col + row] + s.b[row] * nKinv[col];
#ifdef FMV3D_PM_AVX2
      costs[i] = use_avx2_ ? NccAvx2(rp, x, y, H, s) : Ncc(rp, x, y, H, s);
#else
      costs[i] = Ncc(rp, x, y, H, s);
#endif
      PMC(g_ncc_calls);
      totals[i] += costs[i];
      if (i + 1 < ns && MayReach(totals, i + 1, ns, k, bound) &&
          k_smallest_sum(order) / static_cast<float>(k) >= bound) {
        PMC(g_pruned);
        return bound;
      }
    }
    // Mean of the best top_k totals (per-pixel view selection).
    const float sum_t = k_smallest_sum(order);
    float sum_p = 0;
    for (int i = 0; i < k; ++i) sum_p += costs[order[i]];
    *photo = sum_p / static_cast<float>(k);
    return sum_t / static_cast<float>(k);
  }

  uint64_t PixelSeed(int x, int y, int round) const {
    return seed_ ^ (static_cast<uint64_t>(round + 1) * 0x2545F4914F6CDD1Dull) ^
           (static_cast<uint64_t>(y) * L_.w + x) * 0x9E3779B97F4A7C15ull;
  }

  // Random planes everywhere (or the given initial planes), then the sparse seeds, then all costs.
  void Initialise(const std::vector<Eigen::Vector3f>* seeds_cam, bool keep_existing) {
    tbb::parallel_for(tbb::blocked_range<int>(0, L_.h, 4), [&](const tbb::blocked_range<int>& rows) {
      for (int y = rows.begin(); y < rows.end(); ++y)
        for (int x = 0; x < L_.w; ++x) {
          const size_t i = static_cast<size_t>(y) * L_.w + x;
          if (keep_existing && depth_[i] > 0) continue;
          Rng rng(PixelSeed(x, y, -1));
          depth_[i] = RandomDepth(rng);
          normal_[i] = RandomNormal(rng, Ray(x, y));
        }
    });
    if (seeds_cam) {
      for (const auto& Xc : *seeds_cam) {
        if (!(Xc.z() > 0)) continue;
        const Eigen::Vector3f p = L_.K * Xc;
        const int cx = static_cast<int>(std::floor(p.x() / p.z())), cy = static_cast<int>(std::floor(p.y() / p.z()));
        for (int y = cy - 1; y <= cy + 1; ++y)
          for (int x = cx - 1; x <= cx + 1; ++x) {
            if (x < 0 || y < 0 || x >= L_.w || y >= L_.h) continue;
            const Eigen::Vector3f ray = Ray(x, y);
            const Eigen::Vector3f n = -Xc.normalized();  // fronto-parallel; refinement tilts it
            const float d = n.dot(Xc) / n.dot(ray);
            if (d >= dmin_ && d <= dmax_) {
              depth_[static_cast<size_t>(y) * L_.w + x] = d;
              normal_[static_cast<size_t>(y) * L_.w + x] = n;
            }
          }
      }
    }
    tbb::parallel_for(tbb::blocked_range<int>(0, L_.h, 4), [&](const tbb::blocked_range<int>& rows) {
      RefPatch rp;
      for (int y = rows.begin(); y < rows.end(); ++y)
        for (int x = 0; x < L_.w; ++x) {
          const size_t i = static_cast<size_t>(y) * L_.w + x;
          ComputeRefPatch(x, y, &rp);
          cost_[i] = Cost(rp, x, y, depth_[i], normal_[i], &photo_[i]);
        }
    });
  }

  // One round: red pixels, then black pixels. `round` sets the refinement range (halved every round).
  void Iterate(int round) {
    for (int colour = 0; colour < 2; ++colour) {
      ++pass_;
      tbb::parallel_for(tbb::blocked_range<int>(0, L_.h, 2), [&](const tbb::blocked_range<int>& rows) {
        RefPatch rp;
        for (int y = rows.begin(); y < rows.end(); ++y)
          for (int x = (y + colour) & 1; x < L_.w; x += 2) UpdatePixel(x, y, round, &rp);
      });
    }
  }

  void UpdatePixel(int x, int y, int round, RefPatch* rp) {
    const size_t i = static_cast<size_t>(y) * L_.w + x;
    ComputeRefPatch(x, y, rp);
    float best_d = depth_[i], best_cost = cost_[i], best_photo = photo_[i];
    Eigen::Vector3f best_n = normal_[i];
    const Eigen::Vector3f ray = Ray(x, y);
    // Converged regions hand the same plane around: a candidate equal to one already scored is skipped
    // (most of the propagation cost after the first rounds).
    float tried_d[16];
    Eigen::Vector3f tried_n[16];
    int n_tried = 0;
    auto trial = [&](float d, const Eigen::Vector3f& n) {
      for (int k = 0; k < n_tried; ++k)
        if (std::abs(d - tried_d[k]) <= 1e-5f * d && n.dot(tried_n[k]) >= 0.99999f) {
          PMC(g_dedup);
          return;
        }
      PMC(g_trials);
      if (n_tried < 16) tried_d[n_tried] = d, tried_n[n_tried++] = n;
      float photo;
      const float c = Cost(*rp, x, y, d, n, &photo, best_cost);
      if (c < best_cost) PMC(g_accept), best_cost = c, best_photo = photo, best_d = d, best_n = n;
    };
    // Propagation: the planes of the opposite colour at distance 1 and 5 (both odd: the other colour).
    tried_d[0] = best_d;
    tried_n[0] = best_n;
    n_tried = 1;
    static const int kOff[8][2] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}, {-5, 0}, {5, 0}, {0, -5}, {0, 5}};
    // A neighbour whose plane has not changed since this pixel's previous update was scored then: its cost is
    // the same now and not below the best (which only decreases), so it is skipped — an exact shortcut that
    // removes most of the propagation work once regions have converged.
    const int last_update = updated_[i];
    for (const auto& o : kOff) {
      const int nx = x + o[0], ny = y + o[1];
      if (nx < 0 || ny < 0 || nx >= L_.w || ny >= L_.h) continue;
      const size_t j = static_cast<size_t>(ny) * L_.w + nx;
      if (changed_[j] < last_update) {
        PMC(g_skip);
        continue;
      }
      const Eigen::Vector3f& n = normal_[j];
      const float den = n.dot(ray);
      if (!(den < 0)) continue;
      const float d = n.dot(depth_[j] * Ray(nx, ny)) / den;  // neighbour's plane through this pixel's ray
      trial(d, n);
    }
    // Random refinement around the best plane, the range halving each round.
    Rng rng(PixelSeed(x, y, round));
    const float scale = std::pow(0.5f, static_cast<float>(round));
    auto perturb_normal = [&](const Eigen::Vector3f& n, float amount) {
      Eigen::Vector3f p = n + amount * Eigen::Vector3f(rng.Symmetric(), rng.Symmetric(), rng.Symmetric());
      p.normalize();
      return p.dot(ray) < 0 ? p : n;
    };
    const float dp = 0.05f * scale, np = 0.5f * scale;
    if (round < 2) {  // fresh guesses only while planes are still far off; later rounds only polish
      trial(RandomDepth(rng), best_n);
      trial(best_d, RandomNormal(rng, ray));
    }
    trial(best_d * (1 + dp * rng.Symmetric()), perturb_normal(best_n, np));
    trial(best_d * (1 + dp * rng.Symmetric()), best_n);
    trial(best_d, perturb_normal(best_n, np));
    updated_[i] = pass_;
    if (best_d != depth_[i] || best_n != normal_[i]) changed_[i] = pass_;
    depth_[i] = best_d;
    normal_[i] = best_n;
    cost_[i] = best_cost;
    photo_[i] = best_photo;
  }

 private:
  const Level& L_;
  const PatchMatchOptions& opt_;
  float dmin_, dmax_;
  uint64_t seed_;
  int side_ = 0, n_samples_ = 0, n_padded_ = 0, radius_ = 0;
  bool use_avx2_ = false;  // 8-lane NCC (NccAvx2) on CPUs that have AVX2 and FMA
  alignas(32) float off_x_[kMaxSamples], off_y_[kMaxSamples];
  // Change tracking for propagation: colour passes are numbered from 1; changed_[i] is the pass in which
  // pixel i's plane last changed (0: initial plane), updated_[i] the pass of its last update (0: none yet).
  int pass_ = 0;
  std::vector<int> changed_, updated_;
  std::vector<float> spatial_;
  float inv_2sc2_ = 0;
};

Eigen::Matrix3f ScaledK(const Eigen::Matrix3d& K, double sx, double sy) {
  Eigen::Matrix3d k = K;
  k.row(0) *= sx;
  k.row(1) *= sy;
  return k.cast<float>();
}

// Builds a level at `factor` of each view's working resolution (1 = full).
Level MakeLevel(const PatchMatchInput& in, double factor) {
  Level L;
  auto resize = [&](const cv::Mat& img) {
    if (factor == 1.0) return img;
    cv::Mat out;
    cv::resize(img, out,
               cv::Size(std::max(8, static_cast<int>(std::lround(img.cols * factor))),
                        std::max(8, static_cast<int>(std::lround(img.rows * factor)))),
               0, 0, cv::INTER_AREA);
    return out;
  };
  const ViewGeometry& rg = in.ref->geom;
  L.ref = resize(in.ref->gray);
  L.w = L.ref.cols;
  L.h = L.ref.rows;
  L.K = ScaledK(rg.K, static_cast<double>(L.w) / rg.width, static_cast<double>(L.h) / rg.height);
  L.Kinv = L.K.inverse();
  L.images.reserve(in.sources.size());
  for (size_t i = 0; i < in.sources.size(); ++i) {
    const View* v = in.sources[i];
    L.images.push_back(resize(v->gray));
    const cv::Mat& img = L.images.back();
    Source s;
    s.img = img.ptr<float>(0);
    s.w = img.cols;
    s.h = img.rows;
    s.stride = img.step1();
    s.K = ScaledK(v->geom.K, static_cast<double>(s.w) / v->geom.width, static_cast<double>(s.h) / v->geom.height);
    const Eigen::Matrix3d R = v->geom.R * rg.R.transpose();
    s.R = R.cast<float>();
    s.t = (v->geom.t - R * rg.t).cast<float>();
    s.A = s.K * s.R * L.Kinv;
    s.b = s.K * s.t;
    if (i < in.source_maps.size() && in.source_maps[i] && factor == 1.0) {
      s.map = in.source_maps[i];
      s.map_K = ScaledK(v->geom.K, static_cast<double>(s.map->width()) / v->geom.width,
                        static_cast<double>(s.map->height()) / v->geom.height);
      s.map_Kinv = s.map_K.inverse();
    }
    L.sources.push_back(s);
  }
  return L;
}

}  // namespace

bool Avx2KernelAvailable() {
#ifdef FMV3D_PM_AVX2
  static const bool available = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return available;
#else
  return false;
#endif
}

void PatchMatchOptions::Check() const {
  if (window_radius < 1 || window_step < 1 || window_step > window_radius)
    throw Error("patch match: need window_radius >= 1 and 1 <= window_step <= window_radius");
  const int side = 2 * (window_radius / window_step) + 1;
  if (side * side > kMaxSamples)
    throw Error("patch match: window too large (at most " + std::to_string(kMaxSamples) +
                " samples; raise window_step)");
  if (!(sigma_color > 0 && sigma_spatial > 0)) throw Error("patch match: sigmas must be positive");
  if (iterations < 1 || fine_iterations < 1 || geom_iterations < 0)
    throw Error("patch match: iterations and fine_iterations must be >= 1, geom_iterations >= 0");
  if (top_k < 1) throw Error("patch match: top_k must be >= 1");
  if (!(geom_weight >= 0 && geom_max_error_px > 0)) throw Error("patch match: bad geometric weight / max error");
  if (!(max_cost > 0 && max_cost <= 2)) throw Error("patch match: max_cost must be in (0, 2]");
}

DepthMap RunPatchMatch(const PatchMatchInput& in, const PatchMatchOptions& opt, PatchMatchStats* stats) {
  opt.Check();
  const auto start = std::chrono::steady_clock::now();
  if (!in.ref) throw Error("patch match: no reference view");
  if (in.sources.empty()) throw Error("patch match: view '" + in.ref->geom.name + "' has no source views");
  if (in.sources.size() > 16) throw Error("patch match: at most 16 source views");
  if (!(in.depth_min > 0 && in.depth_max > in.depth_min))
    throw Error("patch match: view '" + in.ref->geom.name + "' has an empty depth range");
  const ViewGeometry& rg = in.ref->geom;
  const uint64_t seed = opt.seed * 0x100000001B3ull + rg.image_id;

  std::vector<Eigen::Vector3f> seeds_cam;
  for (const auto& X : in.seeds) seeds_cam.push_back((rg.R * X + rg.t).cast<float>());

  const Level fine = MakeLevel(in, 1.0);
  Solver solver(fine, opt, in.depth_min, in.depth_max, seed);
  const bool geometric = in.init != nullptr;
  if (geometric) {
    // Geometric pass: start from the photometric planes, refine with small perturbations only.
    for (int y = 0; y < fine.h; ++y)
      for (int x = 0; x < fine.w; ++x) {
        const size_t i = static_cast<size_t>(y) * fine.w + x;
        solver.depth_[i] = in.init->depth.at<float>(y, x);
        const cv::Vec3f n = in.init->normal.at<cv::Vec3f>(y, x);
        solver.normal_[i] = Eigen::Vector3f(n[0], n[1], n[2]);
      }
    solver.Initialise(nullptr, true);
    for (int r = 0; r < opt.geom_iterations; ++r) solver.Iterate(r + 3);
  } else if (opt.coarse_to_fine && std::max(fine.w, fine.h) >= opt.coarse_min_size) {
    const Level coarse = MakeLevel(in, 0.5);
    Solver cs(coarse, opt, in.depth_min, in.depth_max, seed ^ 0xC0A25Eull);
    cs.Initialise(&seeds_cam, false);
    for (int r = 0; r < opt.iterations; ++r) cs.Iterate(r);
    for (int y = 0; y < fine.h; ++y)
      for (int x = 0; x < fine.w; ++x) {
        const int cx = std::min(coarse.w - 1, x * coarse.w / fine.w),
                  cy = std::min(coarse.h - 1, y * coarse.h / fine.h);
        const size_t i = static_cast<size_t>(y) * fine.w + x, j = static_cast<size_t>(cy) * coarse.w + cx;
        // The coarse plane, re-intersected with this pixel's ray.
        const Eigen::Vector3f& n = cs.normal_[j];
        const float den = n.dot(solver.Ray(x, y));
        const Eigen::Vector3f Xc = cs.depth_[j] * cs.Ray(cx, cy);
        const float d = den < 0 ? n.dot(Xc) / den : cs.depth_[j];
        solver.depth_[i] = d;
        solver.normal_[i] = n;
      }
    solver.Initialise(nullptr, true);
    for (int r = 0; r < opt.fine_iterations; ++r) solver.Iterate(r + 2);
  } else {
    solver.Initialise(&seeds_cam, false);
    for (int r = 0; r < opt.iterations; ++r) solver.Iterate(r);
  }

  DepthMap out;
  out.depth.create(fine.h, fine.w, CV_32F);
  out.normal.create(fine.h, fine.w, CV_32FC3);
  out.cost.create(fine.h, fine.w, CV_32F);
  int valid = 0;
  for (int y = 0; y < fine.h; ++y)
    for (int x = 0; x < fine.w; ++x) {
      const size_t i = static_cast<size_t>(y) * fine.w + x;
      const bool ok = solver.photo_[i] <= opt.max_cost && solver.depth_[i] > 0;
      out.depth.at<float>(y, x) = ok ? solver.depth_[i] : 0.f;
      const Eigen::Vector3f& n = solver.normal_[i];
      out.normal.at<cv::Vec3f>(y, x) = cv::Vec3f(n.x(), n.y(), n.z());
      out.cost.at<float>(y, x) = solver.photo_[i];
      valid += ok;
    }
#ifdef PM_COUNT
  std::fprintf(stderr, "cost %ld ncc %ld pruned %ld trials %ld dedup %ld accept %ld skipped %ld\n", g_cost_calls.load(),
               g_ncc_calls.load(), g_pruned.load(), g_trials.load(), g_dedup.load(), g_accept.load(), g_skip.load());
#endif
  if (stats) {
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    stats->valid_pixels = valid;
  }
  return out;
}

}  // namespace fmv3d::mvs
