// The memory the `features` stage needs, and how it stays under `--max-memory`.
//
// OpenCV's SIFT doubles its input (first octave −1) and keeps, per octave, octave_layers + 3 Gaussian and
// octave_layers + 2 difference-of-Gaussian float images: 4 bytes × 4 (doubled) × 11 × 4/3 (octaves) ≈ 235 bytes per
// pixel of the image it is given, plus the transient float copies of its initial image. At 12 MP (extracted at
// 3200x2400) that is ≈ 1.8 GB for one image. The stage therefore
//   - estimates each image's working set from its pixel count (PlanSiftMemory, a model fitted to measured peaks
//     with a margin: bench/results/feat11.md),
//   - runs an image only while the estimates in flight fit the budget (MemoryGate; one image is always admitted),
//   - and, when one whole image alone exceeds the budget, runs SIFT on overlapping tiles (PlanSiftTiles) whose
//     working sets fit it.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <mutex>
#include <vector>

namespace fmv3d::features {

struct SiftOptions;

// Bytes per pixel of the image SIFT is given (pyramid + initial image copies): the peak RSS of one image on one
// thread grows by 236 bytes per extraction pixel from 0.5 to 4.3 MP (bench/results/feat11.md; theory 235); 250
// keeps a 6% margin.
constexpr double kSiftBytesPerPixel = 250;
// Bytes per pixel of the decoded frame: BGR (3) + its grey copy (1).
constexpr double kFrameBytesPerPixel = 4;
// Descriptors (float and uint8), keypoints and OpenCV's per-call buffers: a fixed allowance.
constexpr double kSiftFixedBytes = 32.0 * 1048576;

struct PixelRect {
  int x = 0, y = 0, width = 0, height = 0;
  long long area() const { return static_cast<long long>(width) * height; }
  bool operator==(const PixelRect& o) const { return x == o.x && y == o.y && width == o.width && height == o.height; }
};

// One SIFT call on part of the extraction image: keypoints are detected on `window` and kept only when they lie in
// `core` (cores partition the image: each keypoint is kept once).
struct SiftTile {
  PixelRect core, window;
};

// Extraction size of a width x height frame (downscaled so that its larger side is at most max_image_size, as
// ExtractSift does).
void ExtractionSize(int width, int height, int max_image_size, int* out_width, int* out_height);

// Estimated bytes of one SIFT call on a window of `pixels` pixels.
double SiftWindowBytes(long long pixels);

struct SiftMemoryPlan {
  int extraction_width = 0, extraction_height = 0;
  std::vector<SiftTile> tiles;  // one tile (window = core = the whole image) when the image fits
  double estimated_bytes = 0;   // frame + the largest tile's SIFT working set: what the image holds at its peak
  bool fits = true;             // false when even the finest tiling exceeds the budget (the image then runs alone)
};

// Tiling of an extraction image of width x height: the fewest tiles whose largest window's SIFT working set plus
// `other_bytes` fits `budget_bytes`. Core edges lie on multiples of `align` pixels and windows extend them by
// `margin` (a multiple of `align`), so that every window's origin is a multiple of `align` and its coarser octaves
// subsample the same pixels as the whole image's. Cores are at least `min_core` pixels wide: when even those do not
// fit, the finest such tiling is returned with fits = false.
struct TilingLimits {
  int margin = 256, align = 64, min_core = 256;
};
std::vector<SiftTile> PlanSiftTiles(int width, int height, double budget_bytes, double other_bytes,
                                    const TilingLimits& limits, bool* fits = nullptr);

// The plan for one frame of width x height under `budget_bytes` (whole image when it fits, tiles otherwise).
SiftMemoryPlan PlanSiftMemory(int width, int height, const SiftOptions& options, double budget_bytes,
                              const TilingLimits& limits = {});

// Whether a request of `request` bytes may start with `in_flight` bytes held by `holders` others: while the sum fits
// the budget, and always when nothing else runs (an image larger than the budget runs alone).
bool Admits(double in_flight, size_t holders, double request, double budget);

// Blocks workers until their estimated bytes are admitted (Admits); records the most bytes and holders in flight.
class MemoryGate {
 public:
  explicit MemoryGate(double budget_bytes) : budget_(budget_bytes) {}
  void Acquire(double bytes);
  void Release(double bytes);
  double peak_bytes() const { return peak_bytes_; }
  size_t peak_holders() const { return peak_holders_; }

 private:
  double budget_;
  double in_flight_ = 0, peak_bytes_ = 0;
  size_t holders_ = 0, peak_holders_ = 0;
  std::mutex mutex_;
  std::condition_variable released_;
};

}  // namespace fmv3d::features
