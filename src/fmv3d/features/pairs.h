// Which image pairs to match: exhaustive (small sets), sequential (video: each frame with the next N and, with
// `quadratic`, frames 2^k ahead), plus loop-closure candidates from a global image descriptor (bag of visual
// words with tf-idf weights on a small k-means vocabulary) so an orbit that comes back to its start is closed.
// `spatial`: frames whose ground footprints (from per-frame telemetry) overlap, see spatial_pairs.h.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "fmv3d/features/types.h"

namespace fmv3d::features {

enum class PairMode { kAuto, kExhaustive, kSequential, kSpatial };
PairMode ParsePairMode(const std::string& name);  // throws fmv3d::Error for an unknown name
const char* PairModeName(PairMode mode);

struct PairOptions {
  PairMode mode = PairMode::kAuto;
  int auto_exhaustive_max_images = 50;  // kAuto: exhaustive up to this many images, else sequential
  int overlap = 10;                     // sequential: each frame with the next `overlap` frames
  bool quadratic = true;                // sequential: also frames i + 2^k beyond the overlap
  int loop_closure_candidates = 5;      // sequential: most similar non-neighbouring frames per frame (0 = off)
  int vocabulary_size = 128;            // visual words for the global descriptor
  int vocabulary_samples_per_image = 100;
  double spatial_overlap_factor = 0.8;  // spatial: pair when centre distance < factor · (r1 + r2)
  int spatial_max_neighbours = 30;      // spatial: nearest overlapping footprints kept per frame
  uint64_t seed = 0;
  void Check() const;
};

struct Footprint;  // spatial_pairs.h

using ImagePair = std::pair<uint32_t, uint32_t>;  // 0-based indices, first < second

std::vector<ImagePair> ExhaustivePairs(size_t num_images);
std::vector<ImagePair> SequentialPairs(size_t num_images, int overlap, bool quadratic);

// Global descriptors: one unit-norm bag-of-words vector per image (rows), from a k-means vocabulary trained on a
// deterministic sample of the descriptors: tf-idf, or, when every word occurs in every frame (idf 0 everywhere),
// smoothed tf-idf minus the collection's mean, which still tells frames apart. Deterministic for a fixed seed.
std::vector<std::vector<float>> GlobalDescriptors(const std::vector<const Descriptors*>& images,
                                                  const PairOptions& options);

// Image i's descriptors, read when a pass needs them (from its feature file in the match stage), so the passes
// over every image hold one image's descriptors per thread instead of all of them.
using DescriptorLoader = std::function<Descriptors(size_t image)>;
std::vector<std::vector<float>> GlobalDescriptors(size_t num_images, const DescriptorLoader& load,
                                                  const PairOptions& options);

// For each image, the `k` most similar images more than `min_gap` frames away (cosine similarity of the
// global descriptors), as sorted unique pairs.
std::vector<ImagePair> LoopClosurePairs(const std::vector<std::vector<float>>& global, int k, int min_gap);

// The pairs for the given mode (kAuto resolved by image count). `used_mode` receives the resolved mode.
// kSpatial needs `footprints` (one per image): frames without a valid footprint are paired sequentially with
// their neighbours; when no frame has one, it falls back (with a warning naming what is missing) to what kAuto
// would choose.
std::vector<ImagePair> SelectPairs(size_t num_images, const DescriptorLoader& load, const PairOptions& options,
                                   PairMode* used_mode = nullptr, size_t* num_loop_closure_pairs = nullptr,
                                   const std::vector<Footprint>* footprints = nullptr);
std::vector<ImagePair> SelectPairs(const std::vector<const Descriptors*>& images, const PairOptions& options,
                                   PairMode* used_mode = nullptr, size_t* num_loop_closure_pairs = nullptr,
                                   const std::vector<Footprint>* footprints = nullptr);

}  // namespace fmv3d::features
