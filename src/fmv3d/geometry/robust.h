// A generic robust estimator over minimal samples: RANSAC (most residuals within a bound) or least median of
// squares (smallest median residual, no bound to guess; tolerates just under 50% outliers).
//
// The problem is a type with
//   using Model = ...;
//   static constexpr int kSampleSize = k;                       // points in a minimal sample
//   size_t NumData() const;
//   bool Fit(const std::vector<size_t>& sample, Model* model) const;  // false: degenerate sample
//   double Residual(const Model& model, size_t i) const;        // ≥ 0, same units as max_residual
// Samples are k distinct indices: every k-subset in lexicographic order when there are at most
// `exhaustive_up_to` data, else `max_iterations` random draws (std::mt19937_64 seeded with `seed`: k indices
// rng() mod n, then each in turn drawn again while it repeats an earlier one): deterministic for a fixed seed.
// Refinement on the inliers (least squares, IRLS, ...) is the caller's, who knows the model's noise.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::geometry {

struct RobustOptions {
  enum class Score {
    kRansac,  // most data with residual ≤ max_residual
    kLMedS,   // smallest median residual
  };
  Score score = Score::kRansac;
  double max_residual = 0;            // kRansac's inlier bound; must be > 0 for it
  int max_iterations = 1000;          // random samples drawn
  size_t exhaustive_up_to = 0;        // every k-subset when NumData() ≤ this (kSampleSize 3: 14 data → 364 subsets)
  bool stop_when_all_inliers = true;  // kRansac: a sample that explains every datum ends the search
  uint64_t seed = 42;
  void Check() const {
    if (score == Score::kRansac && !(max_residual > 0)) throw Error("robust estimator: max_residual must be > 0");
    if (max_iterations < 1) throw Error("robust estimator: max_iterations must be ≥ 1");
  }
};

template <typename Model>
struct RobustResult {
  bool found = false;  // some sample gave a model
  Model model{};
  double score = std::numeric_limits<double>::infinity();  // kLMedS: the median residual; kRansac: −inliers
  std::vector<char> inliers;  // kRansac: residual ≤ max_residual under `model`; kLMedS: empty
  size_t num_inliers = 0;
  int samples_tried = 0;
};

namespace internal {

// Calls visit(sample) for each sample of k distinct indices out of n, as described above; stops when visit
// returns false.
template <typename Visit>
void ForEachSample(size_t n, int k, const RobustOptions& o, Visit visit) {
  std::vector<size_t> sample(static_cast<size_t>(k));
  if (n < static_cast<size_t>(k) || k < 1) return;
  if (n <= o.exhaustive_up_to) {
    for (int i = 0; i < k; ++i) sample[i] = static_cast<size_t>(i);
    while (true) {
      if (!visit(sample)) return;
      int i = k - 1;  // next combination in lexicographic order
      while (i >= 0 && sample[i] == n - static_cast<size_t>(k - i)) --i;
      if (i < 0) return;
      ++sample[i];
      for (int j = i + 1; j < k; ++j) sample[j] = sample[j - 1] + 1;
    }
  }
  std::mt19937_64 rng(o.seed);
  for (int it = 0; it < o.max_iterations; ++it) {
    for (int i = 0; i < k; ++i) sample[i] = rng() % n;
    for (int i = 1; i < k; ++i) {
      const auto repeats = [&] {
        for (int j = 0; j < i; ++j)
          if (sample[j] == sample[i]) return true;
        return false;
      };
      while (repeats()) sample[i] = rng() % n;
    }
    if (!visit(sample)) return;
  }
}

}  // namespace internal

// The best model over the samples (see above); result.found is false when every sample was degenerate.
template <typename Problem>
RobustResult<typename Problem::Model> EstimateRobust(const Problem& problem, const RobustOptions& o) {
  o.Check();
  using Model = typename Problem::Model;
  RobustResult<Model> best;
  const size_t n = problem.NumData();
  std::vector<double> residuals(n);
  internal::ForEachSample(n, Problem::kSampleSize, o, [&](const std::vector<size_t>& sample) {
    ++best.samples_tried;
    Model m;
    if (!problem.Fit(sample, &m)) return true;
    double score = 0;
    if (o.score == RobustOptions::Score::kLMedS) {
      for (size_t i = 0; i < n; ++i) residuals[i] = problem.Residual(m, i);
      score = core::Median(residuals);
    } else {
      size_t count = 0;
      for (size_t i = 0; i < n; ++i) count += problem.Residual(m, i) <= o.max_residual;
      score = -static_cast<double>(count);
    }
    if (score < best.score) {
      best.score = score, best.model = m, best.found = true;
      if (o.score == RobustOptions::Score::kRansac && o.stop_when_all_inliers && -score >= static_cast<double>(n))
        return false;
    }
    return true;
  });
  if (best.found && o.score == RobustOptions::Score::kRansac) {
    best.inliers.assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
      best.inliers[i] = problem.Residual(best.model, i) <= o.max_residual;
      best.num_inliers += best.inliers[i];
    }
  }
  return best;
}

}  // namespace fmv3d::geometry
