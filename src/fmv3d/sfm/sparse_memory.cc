#include "fmv3d/sfm/sparse_memory.h"

#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

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

double EstimateSparseMemoryMb(size_t observations, size_t keypoints, size_t correspondences,
                              const SparseMemoryModel& model) {
  const double bytes = model.bytes_per_observation * static_cast<double>(observations) +
                       model.bytes_per_keypoint * static_cast<double>(keypoints) +
                       model.bytes_per_correspondence * static_cast<double>(correspondences);
  return bytes / 1048576.0;
}

}  // namespace fmv3d::sfm
