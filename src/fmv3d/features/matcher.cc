#include "fmv3d/features/matcher.h"

#include <immintrin.h>

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/flann.hpp>

#include "fmv3d/core/error.h"

namespace fmv3d::features {

void MatchOptions::Check() const {
  if (!(ratio > 0 && ratio <= 1)) throw Error("match: --ratio must be in (0, 1]");
  if (flann_trees < 1 || flann_trees > 32) throw Error("match: FLANN trees must be in [1, 32]");
  if (flann_checks < 1) throw Error("match: FLANN checks must be >= 1");
}

ImageDescriptors::ImageDescriptors(const Descriptors& d, uint32_t id) : u8_(&d), id_(id) {}

ImageDescriptors::~ImageDescriptors() = default;

const cv::Mat& ImageDescriptors::data() {
  std::call_once(once_float_, [&] {
    cv::Mat u8(size(), 128, CV_8U, const_cast<uint8_t*>(u8_->data()));
    u8.convertTo(data_, CV_32F);
  });
  return data_;
}

void ImageDescriptors::BuildInt16() {
  std::call_once(once_int16_, [&] {
    const int n = size();
    const int n4 = (n + 3) / 4 * 4, n16 = (n + 15) / 16 * 16;
    rows16_.assign(size_t(n4) * 128, 0);
    blocks16_.assign(size_t(n16) * 128, 0);
    // Padding descriptors get a huge norm so they never become anyone's neighbour (sums stay below 2^31).
    norms_.assign(n16, 1 << 29);
    for (int i = 0; i < n; ++i) {
      int32_t norm = 0;
      for (int k = 0; k < 128; ++k) {
        const int16_t v = (*u8_)(i, k);
        rows16_[size_t(i) * 128 + k] = v;
        norm += int32_t(v) * v;
        const int b = i / 16, m = i % 16, pair = k / 2;
        blocks16_[((size_t(b) * 64 + pair) * 16 + m) * 2 + (k & 1)] = v;
      }
      norms_[i] = norm;
    }
  });
}

void ImageDescriptors::BuildInt8() {
  BuildInt16();  // the norms
  std::call_once(once_int8_, [&] {
    const int n = size();
    const int n4 = (n + 3) / 4 * 4, n16 = (n + 15) / 16 * 16;
    rows8_.assign(size_t(n4) * 128, 0);
    blocks8_.assign(size_t(n16) * 128, 0);  // padding descriptors: 128 in every dimension (norm keeps them out)
    sums_.assign(n4, 0);
    for (int i = 0; i < n; ++i) {
      int32_t sum = 0;
      for (int k = 0; k < 128; ++k) {
        const uint8_t v = (*u8_)(i, k);
        rows8_[size_t(i) * 128 + k] = v;
        sum += v;
        const int b = i / 16, m = i % 16, g = k / 4;
        blocks8_[((size_t(b) * 32 + g) * 16 + m) * 4 + (k & 3)] = static_cast<int8_t>(int(v) - 128);
      }
      sums_[i] = sum;
    }
  });
}

cv::flann::Index& ImageDescriptors::Index(const MatchOptions& options) {
  data();
  std::call_once(once_index_, [&] {
    static std::mutex rand_mutex;  // FLANN uses the process-wide std::rand state
    std::lock_guard<std::mutex> lock(rand_mutex);
    std::srand(static_cast<unsigned>(options.seed ^ (0x9e3779b9u * (id_ + 1))));
    index_ = std::make_unique<cv::flann::Index>(data_, cv::flann::KDTreeIndexParams(options.flann_trees),
                                                cvflann::FLANN_DIST_L2);
  });
  return *index_;
}

MatcherType ChooseMatcher(int n1, int n2, const MatchOptions& options) {
  if (options.type != MatcherType::kAuto) return options.type;
  return double(n1) * n2 <= options.brute_force_max_product ? MatcherType::kBruteForce : MatcherType::kFlann;
}

namespace {

struct Best2 {
  float d1 = std::numeric_limits<float>::max(), d2 = std::numeric_limits<float>::max();
  int i1 = -1;
  void Add(float d, int i) {
    if (d < d1) {
      d2 = d1;
      d1 = d;
      i1 = i;
    } else if (d < d2) {
      d2 = d;
    }
  }
  // Squared distances: d1 < ratio² d2.
  bool Passes(double ratio_sq) const { return i1 >= 0 && d1 < ratio_sq * d2; }
};

}  // namespace

// Exact 2-NN both ways from one pass over all descriptor pairs. Squared distances |a|² + |b|² − 2 a·b in exact
// int32 arithmetic; an AVX2 kernel (16-bit multiply-add over pairs of dimensions, 4 query rows x 16 candidates
// per step) computes them and tests them against the running second-best of rows and columns in SIMD, so the
// scalar best-2 update only runs for the few distances that improve something. Scalar fallback otherwise.
struct BruteForceAccess {
  struct Best2Arrays {
    std::vector<int32_t> d1, d2, i1;
    explicit Best2Arrays(size_t n) : d1(n, INT32_MAX), d2(n, INT32_MAX), i1(n, -1) {}
    void Add(size_t k, int32_t d, int32_t idx) {
      if (d < d1[k]) {
        d2[k] = d1[k];
        d1[k] = d;
        i1[k] = idx;
      } else if (d < d2[k]) {
        d2[k] = d;
      }
    }
    bool Passes(size_t k, double ratio_sq) const { return i1[k] >= 0 && d1[k] < ratio_sq * d2[k]; }
  };

  // Rows i0..i0+3 of A against block b (descriptors 16b..16b+15) of B.
  static void BlockScalar(const int16_t* a_rows, const int16_t* block, const int32_t* na, const int32_t* nb, int i0,
                          int j0, Best2Arrays* rows, Best2Arrays* cols) {
    for (int r = 0; r < 4; ++r)
      for (int m = 0; m < 16; ++m) {
        int32_t dot = 0;
        for (int pair = 0; pair < 64; ++pair)
          dot += int32_t(a_rows[r * 128 + 2 * pair]) * block[(pair * 16 + m) * 2] +
                 int32_t(a_rows[r * 128 + 2 * pair + 1]) * block[(pair * 16 + m) * 2 + 1];
        const int32_t d = na[r] + nb[m] - 2 * dot;
        if (d < rows->d2[i0 + r]) rows->Add(i0 + r, d, j0 + m);
        if (d < cols->d2[j0 + m]) cols->Add(j0 + m, d, i0 + r);
      }
  }

  __attribute__((target("avx2"))) static void BlockAvx2(const int16_t* a_rows, const int16_t* block, const int32_t* na,
                                                        const int32_t* nb, int i0, int j0, Best2Arrays* rows,
                                                        Best2Arrays* cols) {
    __m256i acc[4][2];
    for (auto& r : acc) r[0] = r[1] = _mm256_setzero_si256();
    for (int pair = 0; pair < 64; ++pair) {
      const __m256i b0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(block + pair * 32));
      const __m256i b1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(block + pair * 32 + 16));
      for (int r = 0; r < 4; ++r) {
        int32_t packed;
        std::memcpy(&packed, a_rows + r * 128 + 2 * pair, 4);
        const __m256i a = _mm256_set1_epi32(packed);
        acc[r][0] = _mm256_add_epi32(acc[r][0], _mm256_madd_epi16(a, b0));
        acc[r][1] = _mm256_add_epi32(acc[r][1], _mm256_madd_epi16(a, b1));
      }
    }
    const __m256i nb0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(nb));
    const __m256i nb1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(nb + 8));
    alignas(32) int32_t d[16];
    for (int r = 0; r < 4; ++r) {
      const __m256i nar = _mm256_set1_epi32(na[r]);
      const __m256i d0 = _mm256_sub_epi32(_mm256_add_epi32(nar, nb0), _mm256_slli_epi32(acc[r][0], 1));
      const __m256i d1 = _mm256_sub_epi32(_mm256_add_epi32(nar, nb1), _mm256_slli_epi32(acc[r][1], 1));
      // Lanes that beat the column's current second best, or this row's.
      const __m256i c0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cols->d2.data() + j0));
      const __m256i c1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cols->d2.data() + j0 + 8));
      const __m256i rr = _mm256_set1_epi32(rows->d2[i0 + r]);
      const int mask_c = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(c0, d0))) |
                         (_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(c1, d1))) << 8);
      const int mask_r = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(rr, d0))) |
                         (_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(rr, d1))) << 8);
      if ((mask_c | mask_r) == 0) continue;
      _mm256_store_si256(reinterpret_cast<__m256i*>(d), d0);
      _mm256_store_si256(reinterpret_cast<__m256i*>(d + 8), d1);
      for (int m = 0; m < 16; ++m) {
        // Re-test: an earlier lane of this row may have tightened the row's bound.
        if (d[m] < rows->d2[i0 + r]) rows->Add(i0 + r, d[m], j0 + m);
        if ((mask_c >> m) & 1) cols->Add(j0 + m, d[m], i0 + r);
      }
    }
  }

  // The same 4 x 16 block with AVX-512 VNNI: vpdpbusd multiplies 4 unsigned bytes of A by 4 signed bytes of B
  // and adds them into a 32-bit lane, so one instruction does 64 multiply-adds (the AVX2 kernel: 16, plus an
  // add). B is stored minus 128 to fit int8: a·b = a·(b − 128) + 128·Σa, exact in int32, so the distances and
  // hence the matches are identical to the other kernels'.
  __attribute__((target("avx512f,avx512bw,avx512vnni"))) static void BlockVnni(const uint8_t* a_rows,
                                                                               const int8_t* block, const int32_t* na,
                                                                               const int32_t* sa, const int32_t* nb,
                                                                               int i0, int j0, Best2Arrays* rows,
                                                                               Best2Arrays* cols) {
    // Two accumulators per row (even and odd groups): eight independent chains hide vpdpbusd's latency.
    __m512i acc[4][2];
    for (auto& r : acc) r[0] = r[1] = _mm512_setzero_si512();
    for (int g = 0; g < 32; g += 2) {
      const __m512i b0 = _mm512_loadu_si512(block + g * 64);
      const __m512i b1 = _mm512_loadu_si512(block + g * 64 + 64);
      for (int r = 0; r < 4; ++r) {
        int32_t p0, p1;
        std::memcpy(&p0, a_rows + r * 128 + 4 * g, 4);
        std::memcpy(&p1, a_rows + r * 128 + 4 * g + 4, 4);
        acc[r][0] = _mm512_dpbusd_epi32(acc[r][0], _mm512_set1_epi32(p0), b0);
        acc[r][1] = _mm512_dpbusd_epi32(acc[r][1], _mm512_set1_epi32(p1), b1);
      }
    }
    const __m512i nbv = _mm512_loadu_si512(nb);
    alignas(64) int32_t d[16];
    for (int r = 0; r < 4; ++r) {
      const __m512i dot = _mm512_add_epi32(_mm512_add_epi32(acc[r][0], acc[r][1]), _mm512_set1_epi32(128 * sa[r]));
      const __m512i dv = _mm512_sub_epi32(_mm512_add_epi32(_mm512_set1_epi32(na[r]), nbv), _mm512_slli_epi32(dot, 1));
      // Lanes that beat the column's current second best, or this row's.
      const __m512i c = _mm512_loadu_si512(cols->d2.data() + j0);
      const __mmask16 mask_c = _mm512_cmpgt_epi32_mask(c, dv);
      const __mmask16 mask_r = _mm512_cmpgt_epi32_mask(_mm512_set1_epi32(rows->d2[i0 + r]), dv);
      if ((mask_c | mask_r) == 0) continue;
      _mm512_store_si512(d, dv);
      for (int m = 0; m < 16; ++m) {
        // Re-test: an earlier lane of this row may have tightened the row's bound.
        if (d[m] < rows->d2[i0 + r]) rows->Add(i0 + r, d[m], j0 + m);
        if ((mask_c >> m) & 1) cols->Add(j0 + m, d[m], i0 + r);
      }
    }
  }

  static bool HasVnni() {
    static const bool vnni = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
                             __builtin_cpu_supports("avx512vnni") && std::getenv("FMV3D_NO_VNNI") == nullptr;
    return vnni;
  }

  static std::vector<FeatureMatch> Run(ImageDescriptors& A, ImageDescriptors& B, const MatchOptions& o) {
    A.BuildInt16();
    B.BuildInt16();
    const int n1 = A.size(), n2 = B.size();
    const int n1p = (n1 + 3) / 4 * 4, num_blocks = (n2 + 15) / 16;
    const double r2 = o.ratio * o.ratio;
    Best2Arrays rows(n1p), cols(size_t(num_blocks) * 16);
    // A's norms padded to a multiple of 4 (A.norms_ is padded to 16).
    if (HasVnni()) {
      A.BuildInt8();
      B.BuildInt8();
      for (int i0 = 0; i0 < n1; i0 += 4) {
        const uint8_t* a_rows = A.rows8_.data() + size_t(i0) * 128;
        for (int b = 0; b < num_blocks; ++b)
          BlockVnni(a_rows, B.blocks8_.data() + size_t(b) * 16 * 128, A.norms_.data() + i0, A.sums_.data() + i0,
                    B.norms_.data() + b * 16, i0, b * 16, &rows, &cols);
      }
    } else {
      static const bool avx2 = __builtin_cpu_supports("avx2");
      auto* block_fn = avx2 ? &BlockAvx2 : &BlockScalar;
      for (int i0 = 0; i0 < n1; i0 += 4) {
        const int16_t* a_rows = A.rows16_.data() + size_t(i0) * 128;
        for (int b = 0; b < num_blocks; ++b)
          block_fn(a_rows, B.blocks16_.data() + size_t(b) * 64 * 32, A.norms_.data() + i0, B.norms_.data() + b * 16, i0,
                   b * 16, &rows, &cols);
      }
    }
    std::vector<FeatureMatch> out;
    for (int r = 0; r < n1; ++r) {
      if (!rows.Passes(r, r2)) continue;
      const int c = rows.i1[r];
      if (c >= n2) continue;
      if (o.mutual && !(cols.Passes(c, r2) && cols.i1[c] == r)) continue;
      out.push_back({static_cast<uint32_t>(r), static_cast<uint32_t>(c)});
    }
    return out;
  }
};

namespace {

std::vector<FeatureMatch> Flann(ImageDescriptors& A, ImageDescriptors& B, const MatchOptions& o) {
  const double r2 = o.ratio * o.ratio;
  const cv::flann::SearchParams search(o.flann_checks);
  cv::Mat idx, dist;
  B.Index(o).knnSearch(A.data(), idx, dist, 2, search);
  std::vector<int> candidate(A.size(), -1);
  std::vector<int> targets;
  for (int r = 0; r < A.size(); ++r) {
    const int* ii = idx.ptr<int>(r);
    const float* dd = dist.ptr<float>(r);
    if (ii[0] < 0 || ii[1] < 0) continue;
    if (dd[0] < r2 * dd[1]) {
      candidate[r] = ii[0];
      targets.push_back(ii[0]);
    }
  }
  std::vector<FeatureMatch> out;
  if (!o.mutual) {
    for (int r = 0; r < A.size(); ++r)
      if (candidate[r] >= 0) out.push_back({uint32_t(r), uint32_t(candidate[r])});
    return out;
  }
  // Reverse check only for the images-2 features that some feature chose.
  std::sort(targets.begin(), targets.end());
  targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
  if (targets.empty()) return out;
  cv::Mat queries(static_cast<int>(targets.size()), 128, CV_32F);
  for (size_t k = 0; k < targets.size(); ++k) B.data().row(targets[k]).copyTo(queries.row(static_cast<int>(k)));
  cv::Mat ridx, rdist;
  A.Index(o).knnSearch(queries, ridx, rdist, 2, search);
  std::vector<int> back(B.size(), -2);
  for (size_t k = 0; k < targets.size(); ++k) {
    const int* ii = ridx.ptr<int>(static_cast<int>(k));
    const float* dd = rdist.ptr<float>(static_cast<int>(k));
    if (ii[0] >= 0 && ii[1] >= 0 && dd[0] < r2 * dd[1]) back[targets[k]] = ii[0];
  }
  for (int r = 0; r < A.size(); ++r)
    if (candidate[r] >= 0 && back[candidate[r]] == r) out.push_back({uint32_t(r), uint32_t(candidate[r])});
  return out;
}

}  // namespace

const char* BruteForceKernelName() {
  if (BruteForceAccess::HasVnni()) return "avx512-vnni";
  return __builtin_cpu_supports("avx2") ? "avx2" : "scalar";
}

std::vector<FeatureMatch> MatchDescriptors(ImageDescriptors& image1, ImageDescriptors& image2,
                                           const MatchOptions& options) {
  if (image1.size() < 2 || image2.size() < 2) return {};
  if (ChooseMatcher(image1.size(), image2.size(), options) == MatcherType::kBruteForce)
    return BruteForceAccess::Run(image1, image2, options);
  return Flann(image1, image2, options);
}

}  // namespace fmv3d::features
