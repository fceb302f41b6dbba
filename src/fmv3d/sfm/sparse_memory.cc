#include "fmv3d/sfm/sparse_memory.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "fmv3d/features/types.h"

namespace fmv3d::sfm {
namespace {

using Masks = std::vector<std::vector<bool>>;

bool InImage(const std::vector<size_t>& keypoints_per_image, uint32_t image_id, uint32_t index) {
  return image_id >= 1 && image_id <= keypoints_per_image.size() && index < keypoints_per_image[image_id - 1];
}

// The counts the pairs would give with only the correspondences whose two keypoints `keep` marks.
SparseMemoryCounts CountKept(const std::vector<size_t>& keypoints_per_image,
                             const std::vector<features::VerifiedPair>& pairs, const Masks& keep) {
  SparseMemoryCounts c;
  Masks matched(keypoints_per_image.size());
  for (size_t i = 0; i < keypoints_per_image.size(); ++i) {
    c.keypoints += keypoints_per_image[i];
    matched[i].assign(keypoints_per_image[i], false);
  }
  auto mark = [&](uint32_t image_id, uint32_t index) {
    std::vector<bool>& seen = matched[image_id - 1];
    if (!seen[index]) {
      seen[index] = true;
      ++c.matched_keypoints;
    }
  };
  for (const auto& pair : pairs)
    for (const auto& m : pair.inliers) {
      if (!InImage(keypoints_per_image, pair.image_id1, m.idx1) ||
          !InImage(keypoints_per_image, pair.image_id2, m.idx2) || !keep[pair.image_id1 - 1][m.idx1] ||
          !keep[pair.image_id2 - 1][m.idx2])
        continue;
      ++c.correspondences;
      mark(pair.image_id1, m.idx1);
      mark(pair.image_id2, m.idx2);
    }
  return c;
}

}  // namespace

SparseMemoryCounts CountSparseMemoryInputs(const std::vector<size_t>& keypoints_per_image,
                                           const std::vector<features::VerifiedPair>& pairs) {
  SparseMemoryCounts c;
  std::vector<std::vector<bool>> matched(keypoints_per_image.size());
  for (size_t i = 0; i < keypoints_per_image.size(); ++i) {
    c.keypoints += keypoints_per_image[i];
    matched[i].assign(keypoints_per_image[i], false);
  }
  auto mark = [&](uint32_t image_id, uint32_t index) {
    if (image_id == 0 || image_id > matched.size() || index >= matched[image_id - 1].size()) return;
    std::vector<bool>& seen = matched[image_id - 1];
    if (!seen[index]) {
      seen[index] = true;
      ++c.matched_keypoints;
    }
  };
  for (const auto& pair : pairs) {
    c.correspondences += pair.inliers.size();
    for (const auto& m : pair.inliers) {
      mark(pair.image_id1, m.idx1);
      mark(pair.image_id2, m.idx2);
    }
  }
  return c;
}

SparseThinning ThinToMemoryBudget(const std::vector<MapperImage>& images,
                                  const std::map<uint32_t, uint32_t>& manual_from, double budget_mb,
                                  std::vector<features::VerifiedPair>* pairs, const SparseMemoryModel& model,
                                  double min_keep_fraction) {
  std::vector<size_t> keypoints_per_image;
  keypoints_per_image.reserve(images.size());
  for (const auto& im : images) keypoints_per_image.push_back(im.keypoints.size());
  SparseThinning t;
  t.before = t.after = CountSparseMemoryInputs(keypoints_per_image, *pairs);
  t.bound_before_mb = t.bound_after_mb = SparseMemoryBoundMb(t.before, model);
  if (t.bound_before_mb <= budget_mb) return t;

  // Each image's matched automatic keypoints in the order they are kept: round robin over the grid cells, each
  // cell's most connected first.
  const size_t n = keypoints_per_image.size();
  std::vector<std::vector<uint32_t>> degree(n);
  for (size_t i = 0; i < n; ++i) degree[i].assign(keypoints_per_image[i], 0);
  for (const auto& pair : *pairs)
    for (const auto& m : pair.inliers) {
      if (!InImage(keypoints_per_image, pair.image_id1, m.idx1) ||
          !InImage(keypoints_per_image, pair.image_id2, m.idx2))
        continue;
      ++degree[pair.image_id1 - 1][m.idx1];
      ++degree[pair.image_id2 - 1][m.idx2];
    }
  auto first_manual = [&](size_t i) {
    const auto it = manual_from.find(static_cast<uint32_t>(i + 1));
    return it == manual_from.end() ? keypoints_per_image[i] : std::min<size_t>(it->second, keypoints_per_image[i]);
  };
  constexpr int kGrid = 8;
  std::vector<std::vector<uint32_t>> ranked(n);
  for (size_t i = 0; i < n; ++i) {
    const auto& kp = images[i].keypoints;
    std::vector<uint32_t> matched;
    Eigen::AlignedBox2d extent;
    for (uint32_t k = 0; k < first_manual(i); ++k)
      if (degree[i][k] > 0) {
        matched.push_back(k);
        extent.extend(kp[k]);
      }
    std::stable_sort(matched.begin(), matched.end(),
                     [&](uint32_t a, uint32_t b) { return degree[i][a] > degree[i][b]; });
    if (matched.empty()) continue;
    const Eigen::Vector2d size = extent.sizes().cwiseMax(1e-9);
    std::vector<std::vector<uint32_t>> cells(static_cast<size_t>(kGrid) * kGrid);
    for (uint32_t k : matched) {
      const Eigen::Vector2d u = (kp[k] - extent.min()).cwiseQuotient(size) * kGrid;
      const int cx = std::clamp(static_cast<int>(u.x()), 0, kGrid - 1);
      const int cy = std::clamp(static_cast<int>(u.y()), 0, kGrid - 1);
      cells[cy * kGrid + cx].push_back(k);
    }
    ranked[i].reserve(matched.size());
    for (size_t r = 0; ranked[i].size() < matched.size(); ++r)
      for (const auto& cell : cells)
        if (r < cell.size()) ranked[i].push_back(cell[r]);
  }
  auto select = [&](double fraction) {
    Masks keep(n);
    for (size_t i = 0; i < n; ++i) {
      keep[i].assign(keypoints_per_image[i], false);
      for (size_t k = first_manual(i); k < keypoints_per_image[i]; ++k) keep[i][k] = true;
      const auto count = static_cast<size_t>(std::ceil(fraction * static_cast<double>(ranked[i].size())));
      for (size_t r = 0; r < count; ++r) keep[i][ranked[i][r]] = true;
    }
    return keep;
  };
  auto bound = [&](double fraction) {
    return SparseMemoryBoundMb(CountKept(keypoints_per_image, *pairs, select(fraction)), model);
  };
  if (bound(min_keep_fraction) > budget_mb) {
    t.fits = false;
    return t;
  }
  double lo = min_keep_fraction, hi = 1;  // lo fits, hi does not
  for (int it = 0; it < 12; ++it) {
    const double mid = 0.5 * (lo + hi);
    (bound(mid) <= budget_mb ? lo : hi) = mid;
  }
  const Masks keep = select(lo);
  for (auto& pair : *pairs) {
    auto& in = pair.inliers;
    const size_t original = in.size();
    in.erase(std::remove_if(in.begin(), in.end(),
                            [&](const features::FeatureMatch& m) {
                              return !InImage(keypoints_per_image, pair.image_id1, m.idx1) ||
                                     !InImage(keypoints_per_image, pair.image_id2, m.idx2) ||
                                     !keep[pair.image_id1 - 1][m.idx1] || !keep[pair.image_id2 - 1][m.idx2];
                            }),
             in.end());
    // The geometry counts keep their ratios to the inliers (the initial pair's homography test reads them).
    if (original > 0 && in.size() < original) {
      const double ratio = static_cast<double>(in.size()) / static_cast<double>(original);
      for (uint32_t* count : {&pair.num_inliers_F, &pair.num_inliers_E, &pair.num_inliers_H})
        *count = static_cast<uint32_t>(std::lround(ratio * *count));
    }
  }
  t.after = CountSparseMemoryInputs(keypoints_per_image, *pairs);
  t.bound_after_mb = SparseMemoryBoundMb(t.after, model);
  t.keep_fraction = lo;
  t.thinned = true;
  return t;
}

double EstimateSparseMemoryMb(size_t observations, size_t keypoints, size_t correspondences,
                              const SparseMemoryModel& model) {
  const double bytes = model.bytes_per_observation * static_cast<double>(observations) +
                       model.bytes_per_keypoint * static_cast<double>(keypoints) +
                       model.bytes_per_correspondence * static_cast<double>(correspondences);
  return bytes / 1048576.0;
}

}  // namespace fmv3d::sfm
