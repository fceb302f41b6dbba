// Descriptor matching between two images: 2 nearest neighbours by FLANN randomized kd-trees or brute force,
// Lowe's ratio test and a mutual (cross) check.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/features/types.h"

namespace cv::flann {
class Index;
}

namespace fmv3d::features {

enum class MatcherType { kAuto, kFlann, kBruteForce };

struct MatchOptions {
  double ratio = 0.8;  // Lowe: nearest / second-nearest distance must be below this
  bool mutual = true;  // keep i↔j only if j's best match in image 1 is i (ratio test both ways)
  MatcherType type = MatcherType::kAuto;
  int flann_trees = 4;
  int flann_checks = 128;  // leaves visited per query: accuracy / speed trade-off
  // kAuto: brute force when n1 * n2 is below this. Measured (bench/match_bench.cc, fountain-P11 SIFT, one core):
  // 8000 x 8000 features: our AVX2 int16 brute force 127 ms (both directions, exact), FLANN (4 trees, 128
  // checks, incl. the two kd-tree builds) 761 ms, OpenCV's batchDistance brute force 930 ms. Brute force grows
  // with n², FLANN about with n: the crossover is near 40000 features per image.
  double brute_force_max_product = 1.3e9;
  uint64_t seed = 0;
  void Check() const;
};

// One image's descriptors with lazily built search structures (thread-safe; each built once): float rows and
// a kd-forest for FLANN, int16 rows + 16-descriptor column blocks for the SIMD brute-force kernel. Keeps a
// pointer to `descriptors`, which must outlive it.
class ImageDescriptors {
 public:
  ImageDescriptors(const Descriptors& descriptors, uint32_t id);
  ~ImageDescriptors();
  int size() const { return static_cast<int>(u8_->rows()); }
  const cv::Mat& data();  // float rows
  // The kd-forest; built on first use. FLANN draws the tree splits from std::rand, so builds are serialised
  // and seeded per image (seed ^ id) for determinism.
  cv::flann::Index& Index(const MatchOptions& options);

 private:
  friend struct BruteForceAccess;
  void BuildInt16();
  void BuildInt8();
  const Descriptors* u8_;
  uint32_t id_;
  std::once_flag once_float_, once_index_, once_int16_, once_int8_;
  cv::Mat data_;
  std::unique_ptr<cv::flann::Index> index_;
  std::vector<int16_t> rows16_;    // n_padded4 x 128, row-major (zero padding rows)
  std::vector<int16_t> blocks16_;  // per 16 descriptors: 64 dim pairs x 16 descriptors x 2 dims
  std::vector<int32_t> norms_;     // |d|^2 per descriptor (padding: a huge norm, never a neighbour)
  // For the AVX-512 VNNI kernel (u8 x s8 dot products, 4 dimensions per 32-bit lane):
  std::vector<uint8_t> rows8_;   // n_padded4 x 128, row-major (zero padding rows)
  std::vector<int8_t> blocks8_;  // per 16 descriptors: 32 groups of 4 dims x 16 descriptors x 4, value − 128
  std::vector<int32_t> sums_;    // sum of the u8 values per descriptor (restores the −128 offset)
};

// Which brute-force distance kernel this CPU runs ("avx512-vnni", "avx2" or "scalar"); all give identical
// matches (exact integer distances). For the bench and the logs.
const char* BruteForceKernelName();

// Ratio-tested (and, with options.mutual, cross-checked) matches from image 1 to image 2, sorted by idx1.
std::vector<FeatureMatch> MatchDescriptors(ImageDescriptors& image1, ImageDescriptors& image2,
                                           const MatchOptions& options);

// For the bench and tests: the matcher kAuto would pick for these sizes.
MatcherType ChooseMatcher(int n1, int n2, const MatchOptions& options);

}  // namespace fmv3d::features
