// Order statistics and moments of samples, the one definition every module uses.
// Conventions: an empty sample gives 0; the median of an even-sized sample is its upper middle element (a value
// of the sample, not an average of two), which is what the robust scale estimates here assume.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace fmv3d::core {

// The element of rank floor(n/2) (0-based) in sorted order.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// Nearest-rank quantile: the element of rank round(q·(n−1)) in sorted order, q clamped to [0, 1].
inline double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  q = std::clamp(q, 0.0, 1.0);
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

inline double Mean(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double sum = 0;
  for (double x : v) sum += x;
  return sum / static_cast<double>(v.size());
}

// Root mean square of the values (not about their mean).
inline double Rms(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double sq = 0;
  for (double x : v) sq += x * x;
  return std::sqrt(sq / static_cast<double>(v.size()));
}

// Robust σ of a zero-centred Gaussian sample from its median absolute value (1.4826 = 1/Φ⁻¹(3/4)).
inline double RobustSigma(const std::vector<double>& abs_values) { return 1.4826 * Median(abs_values); }

}  // namespace fmv3d::core
