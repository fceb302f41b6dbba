#include "fmv3d/features/feature_compare.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace fmv3d::features {
namespace {

double DescriptorDistance(const Descriptors& a, size_t i, const Descriptors& b, size_t j) {
  double sum = 0;
  for (int k = 0; k < 128; ++k) {
    const double d = double(a(static_cast<Eigen::Index>(i), k)) - double(b(static_cast<Eigen::Index>(j), k));
    sum += d * d;
  }
  return std::sqrt(sum);
}

double AngleDifference(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 2 * M_PI);
  return std::min(d, 2 * M_PI - d);
}

}  // namespace

KeypointAgreement CompareKeypoints(const FeatureSet& reference, const FeatureSet& other, double tolerance_px) {
  KeypointAgreement r;
  r.reference = reference.keypoints.size();
  r.other = other.keypoints.size();
  std::vector<size_t> by_x(r.other);
  for (size_t j = 0; j < r.other; ++j) by_x[j] = j;
  const auto& ok = other.keypoints;
  std::sort(by_x.begin(), by_x.end(), [&](size_t a, size_t b) { return ok[a].x < ok[b].x; });
  double distance_sum = 0;
  for (size_t i = 0; i < r.reference; ++i) {
    const Keypoint& k = reference.keypoints[i];
    auto it =
        std::lower_bound(by_x.begin(), by_x.end(), k.x - tolerance_px, [&](size_t j, double x) { return ok[j].x < x; });
    double best = -1;
    bool same = false;
    for (; it != by_x.end() && ok[*it].x <= k.x + tolerance_px; ++it) {
      const Keypoint& o = ok[*it];
      if (std::abs(o.y - k.y) > tolerance_px || std::abs(o.scale - k.scale) > 0.01 * k.scale ||
          AngleDifference(o.orientation, k.orientation) > 0.01)
        continue;
      const double d = DescriptorDistance(reference.descriptors, i, other.descriptors, *it);
      if (best < 0 || d < best) best = d;
      same = same || (d == 0 && o.x == k.x && o.y == k.y && o.scale == k.scale && o.orientation == k.orientation);
    }
    if (best < 0) continue;
    ++r.within;
    r.identical += same;
    distance_sum += best;
    r.max_descriptor_distance = std::max(r.max_descriptor_distance, best);
  }
  r.mean_descriptor_distance = r.within ? distance_sum / r.within : 0;
  return r;
}

KeypointAgreement Accumulate(const KeypointAgreement& a, const KeypointAgreement& b) {
  KeypointAgreement r;
  r.reference = a.reference + b.reference;
  r.other = a.other + b.other;
  r.identical = a.identical + b.identical;
  r.within = a.within + b.within;
  r.mean_descriptor_distance =
      r.within ? (a.mean_descriptor_distance * a.within + b.mean_descriptor_distance * b.within) / r.within : 0;
  r.max_descriptor_distance = std::max(a.max_descriptor_distance, b.max_descriptor_distance);
  return r;
}

}  // namespace fmv3d::features
