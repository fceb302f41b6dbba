#include "fmv3d/features/pairs.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/core.hpp>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/features/spatial_pairs.h"

namespace fmv3d::features {

PairMode ParsePairMode(const std::string& name) {
  if (name == "auto") return PairMode::kAuto;
  if (name == "exhaustive") return PairMode::kExhaustive;
  if (name == "sequential") return PairMode::kSequential;
  if (name == "spatial") return PairMode::kSpatial;
  throw Error("match: unknown pair mode '" + name + "' (auto, exhaustive, sequential, spatial)");
}

const char* PairModeName(PairMode mode) {
  switch (mode) {
    case PairMode::kAuto:
      return "auto";
    case PairMode::kExhaustive:
      return "exhaustive";
    case PairMode::kSequential:
      return "sequential";
    case PairMode::kSpatial:
      return "spatial";
  }
  return "?";
}

void PairOptions::Check() const {
  if (overlap < 1) throw Error("match: --overlap must be >= 1");
  if (loop_closure_candidates < 0) throw Error("match: --loop-closure must be >= 0");
  if (vocabulary_size < 2) throw Error("match: vocabulary size must be >= 2");
  if (vocabulary_samples_per_image < 1) throw Error("match: vocabulary samples must be >= 1");
  if (!(spatial_overlap_factor > 0)) throw Error("match: spatial overlap factor must be > 0");
  if (spatial_max_neighbours < 1) throw Error("match: spatial max neighbours must be >= 1");
}

std::vector<ImagePair> ExhaustivePairs(size_t n) {
  std::vector<ImagePair> out;
  for (uint32_t i = 0; i < n; ++i)
    for (uint32_t j = i + 1; j < n; ++j) out.emplace_back(i, j);
  return out;
}

std::vector<ImagePair> SequentialPairs(size_t n, int overlap, bool quadratic) {
  std::set<ImagePair> s;
  for (uint32_t i = 0; i < n; ++i) {
    for (uint32_t d = 1; d <= static_cast<uint32_t>(overlap) && i + d < n; ++d) s.emplace(i, i + d);
    if (quadratic)
      for (uint64_t d = 1; i + d < n; d *= 2)
        if (d > static_cast<uint64_t>(overlap)) s.emplace(i, static_cast<uint32_t>(i + d));
  }
  return {s.begin(), s.end()};
}

namespace {

DescriptorLoader LoaderOf(const std::vector<const Descriptors*>& images) {
  return [&images](size_t i) { return *images[i]; };
}

}  // namespace

std::vector<std::vector<float>> GlobalDescriptors(const std::vector<const Descriptors*>& images, const PairOptions& o) {
  return GlobalDescriptors(images.size(), LoaderOf(images), o);
}

std::vector<std::vector<float>> GlobalDescriptors(size_t n, const DescriptorLoader& load, const PairOptions& o) {
  // Deterministic strided sample of every image's descriptors for the vocabulary.
  std::vector<cv::Mat> per_image(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    const Descriptors d = load(i);
    const int rows = static_cast<int>(d.rows());
    const int take = std::min(rows, o.vocabulary_samples_per_image);
    if (take == 0) return;
    cv::Mat m(take, 128, CV_32F);
    for (int k = 0; k < take; ++k) {
      const int r = static_cast<int>(int64_t(k) * rows / take);
      for (int c = 0; c < 128; ++c) m.at<float>(k, c) = d(r, c);
    }
    per_image[i] = m;
  });
  std::vector<cv::Mat> samples;
  int total = 0;
  for (const auto& m : per_image)
    if (!m.empty()) {
      samples.push_back(m);
      total += m.rows;
    }
  std::vector<std::vector<float>> out(n);
  const int k = std::min(o.vocabulary_size, total);
  if (k < 2) {
    for (auto& v : out) v.assign(1, 0.f);
    return out;
  }
  cv::Mat all, labels, centres;
  cv::vconcat(samples, all);
  cv::theRNG().state = o.seed * 6364136223846793005ULL + 1442695040888963407ULL;
  cv::kmeans(all, k, labels, cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 10, 1e-3), 1,
             cv::KMEANS_PP_CENTERS, centres);

  // Word histograms (every descriptor votes for its nearest centre), then tf-idf, centred, and unit norm.
  std::vector<std::vector<float>> hist(n, std::vector<float>(k, 0.f));
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    const Descriptors d = load(i);
    if (d.rows() == 0) return;
    cv::Mat u8(static_cast<int>(d.rows()), 128, CV_8U, const_cast<uint8_t*>(d.data())), f;
    u8.convertTo(f, CV_32F);
    cv::Mat dist, nidx;
    cv::batchDistance(f, centres, dist, CV_32F, nidx, cv::NORM_L2SQR, 1);
    for (int r = 0; r < nidx.rows; ++r) hist[i][nidx.at<int>(r, 0)] += 1.f;
  });
  // Plain tf-idf (log n/df) while some word is missing from some frame. With thousands of features per frame
  // and a small vocabulary every word occurs in every frame: idf is then 0 everywhere and every descriptor
  // would be zero (no loop closure found at all). In that case the smoothed idf, log((1 + n)/(1 + df)) + 1,
  // never 0, and centring: each image's weighted word frequencies minus the collection's mean, so the
  // component every frame shares (the scene's overall texture statistics) drops out and the cosine compares
  // what is particular to each view.
  std::vector<double> df(k, 0);
  for (const auto& h : hist)
    for (int w = 0; w < k; ++w) df[w] += h[w] > 0;
  const bool degenerate = std::all_of(df.begin(), df.end(), [&](double d) { return d >= double(n); });
  if (!degenerate) {
    for (size_t i = 0; i < n; ++i) {
      const double count = std::accumulate(hist[i].begin(), hist[i].end(), 0.0);
      double norm = 0;
      out[i].assign(k, 0.f);
      for (int w = 0; w < k; ++w) {
        if (hist[i][w] == 0) continue;
        const double v = (hist[i][w] / count) * std::log(double(n) / df[w]);
        out[i][w] = static_cast<float>(v);
        norm += v * v;
      }
      if (norm > 0)
        for (auto& v : out[i]) v = static_cast<float>(v / std::sqrt(norm));
    }
    return out;
  }
  std::vector<std::vector<double>> tfidf(n, std::vector<double>(k, 0.0));
  std::vector<double> mean(k, 0.0);
  size_t used = 0;
  for (size_t i = 0; i < n; ++i) {
    const double count = std::accumulate(hist[i].begin(), hist[i].end(), 0.0);
    if (count == 0) continue;
    ++used;
    for (int w = 0; w < k; ++w) {
      tfidf[i][w] = (hist[i][w] / count) * (std::log((1.0 + n) / (1.0 + df[w])) + 1);
      mean[w] += tfidf[i][w];
    }
  }
  if (used > 0)
    for (auto& m : mean) m /= used;
  for (size_t i = 0; i < n; ++i) {
    out[i].assign(k, 0.f);
    if (hist[i].empty() || std::accumulate(hist[i].begin(), hist[i].end(), 0.0) == 0) continue;
    double norm = 0;
    for (int w = 0; w < k; ++w) norm += (tfidf[i][w] - mean[w]) * (tfidf[i][w] - mean[w]);
    if (norm > 0)
      for (int w = 0; w < k; ++w) out[i][w] = static_cast<float>((tfidf[i][w] - mean[w]) / std::sqrt(norm));
  }
  return out;
}

std::vector<ImagePair> LoopClosurePairs(const std::vector<std::vector<float>>& g, int k, int min_gap) {
  const size_t n = g.size();
  std::set<ImagePair> s;
  if (k <= 0) return {};
  for (size_t i = 0; i < n; ++i) {
    std::vector<std::pair<float, uint32_t>> sims;
    for (size_t j = 0; j < n; ++j) {
      if (std::abs(static_cast<long>(i) - static_cast<long>(j)) <= min_gap) continue;
      float dot = 0;
      for (size_t w = 0; w < g[i].size(); ++w) dot += g[i][w] * g[j][w];
      sims.emplace_back(-dot, static_cast<uint32_t>(j));  // ascending = most similar first; ties by index
    }
    const size_t take = std::min<size_t>(k, sims.size());
    std::partial_sort(sims.begin(), sims.begin() + take, sims.end());
    for (size_t m = 0; m < take; ++m) {
      if (-sims[m].first <= 0) break;
      const uint32_t a = static_cast<uint32_t>(i), b = sims[m].second;
      s.emplace(std::min(a, b), std::max(a, b));
    }
  }
  return {s.begin(), s.end()};
}

std::vector<ImagePair> SelectPairs(const std::vector<const Descriptors*>& images, const PairOptions& o,
                                   PairMode* used_mode, size_t* num_loop_closure_pairs,
                                   const std::vector<Footprint>* footprints) {
  return SelectPairs(images.size(), LoaderOf(images), o, used_mode, num_loop_closure_pairs, footprints);
}

std::vector<ImagePair> SelectPairs(size_t num_images, const DescriptorLoader& load, const PairOptions& o,
                                   PairMode* used_mode, size_t* num_loop_closure_pairs,
                                   const std::vector<Footprint>* footprints) {
  o.Check();
  PairMode mode = o.mode;
  const PairMode by_count =
      num_images <= static_cast<size_t>(o.auto_exhaustive_max_images) ? PairMode::kExhaustive : PairMode::kSequential;
  if (mode == PairMode::kAuto) mode = by_count;
  if (num_loop_closure_pairs) *num_loop_closure_pairs = 0;
  if (mode == PairMode::kSpatial) {
    size_t valid = 0;
    std::string why = "no footprints given";
    if (footprints) {
      if (footprints->size() != num_images)
        throw Error("match: " + std::to_string(footprints->size()) + " footprints for " + std::to_string(num_images) +
                    " images");
      for (const auto& f : *footprints) {
        valid += f.valid;
        if (!f.valid) why = f.why_invalid;
      }
    }
    if (valid == 0) {
      spdlog::warn(
          "match: --pairs spatial needs per-frame telemetry (sensor latitude/longitude and altitude in "
          "frames.json) and none of the {} frames has it ({}); falling back to {} pairs",
          num_images, why, PairModeName(by_count));
      mode = by_count;
    } else {
      if (used_mode) *used_mode = mode;
      std::set<ImagePair> s;
      for (const auto& p : SpatialPairs(*footprints, o.spatial_overlap_factor, o.spatial_max_neighbours)) s.insert(p);
      // Frames without a footprint: their sequential neighbours (the index is in flight order for video).
      const auto seq = SequentialPairs(num_images, o.overlap, false);
      for (const auto& p : seq)
        if (!(*footprints)[p.first].valid || !(*footprints)[p.second].valid) s.insert(p);
      if (valid < num_images)
        spdlog::warn(
            "match: {} of {} frames have no telemetry footprint ({}); paired with their {} sequential "
            "neighbours",
            num_images - valid, num_images, why, o.overlap);
      return {s.begin(), s.end()};
    }
  }
  if (used_mode) *used_mode = mode;
  if (mode == PairMode::kExhaustive) return ExhaustivePairs(num_images);
  auto seq = SequentialPairs(num_images, o.overlap, o.quadratic);
  if (o.loop_closure_candidates > 0 && num_images > static_cast<size_t>(o.overlap) + 1) {
    const auto loops = LoopClosurePairs(GlobalDescriptors(num_images, load, o), o.loop_closure_candidates, o.overlap);
    std::set<ImagePair> s(seq.begin(), seq.end());
    size_t added = 0;
    for (const auto& p : loops) added += s.insert(p).second;
    if (num_loop_closure_pairs) *num_loop_closure_pairs = added;
    seq.assign(s.begin(), s.end());
  }
  return seq;
}

}  // namespace fmv3d::features
