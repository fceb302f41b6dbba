// The correspondence graph: for every keypoint of every image, the keypoints of other images it was matched to
// in a verified pair. The mapper walks it to find 2D–3D correspondences, to continue and create tracks and to
// merge them, deciding per observation by reprojection error. (A global union-find of matches into tracks
// before reconstruction would let a single wrong match chain unrelated tracks together; here a wrong match
// simply fails its reprojection check.)
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

class CorrespondenceGraph {
 public:
  // num_keypoints: image id → keypoint count. Pairs naming unknown images or out-of-range keypoints are skipped
  // (bad input never crashes the mapper); duplicate matches are kept once.
  CorrespondenceGraph(const std::map<uint32_t, size_t>& num_keypoints,
                      const std::vector<features::VerifiedPair>& pairs);

  const std::vector<core::TrackElement>& Correspondences(uint32_t image_id, uint32_t kp) const;
  // True when the keypoint and its only correspondence have no other correspondence: a track of two views,
  // which no third image can ever observe.
  bool IsTwoViewObservation(uint32_t image_id, uint32_t kp) const;
  // Number of images matched to this one, and of its keypoints with ≥ 1 correspondence.
  int NumPairs(uint32_t image_id) const;
  int NumObservedKeypoints(uint32_t image_id) const;
  size_t NumCorrespondences() const { return num_correspondences_; }
  size_t NumSkipped() const { return num_skipped_; }

 private:
  std::map<uint32_t, std::vector<std::vector<core::TrackElement>>> corrs_;
  std::map<uint32_t, int> num_pairs_;
  size_t num_correspondences_ = 0, num_skipped_ = 0;
  static const std::vector<core::TrackElement> kEmpty;
};

}  // namespace fmv3d::sfm
