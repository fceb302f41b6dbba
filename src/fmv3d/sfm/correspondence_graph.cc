#include "fmv3d/sfm/correspondence_graph.h"

#include <algorithm>

namespace fmv3d::sfm {

const std::vector<core::TrackElement> CorrespondenceGraph::kEmpty;

CorrespondenceGraph::CorrespondenceGraph(const std::map<uint32_t, size_t>& num_keypoints,
                                         const std::vector<features::VerifiedPair>& pairs) {
  for (const auto& [id, n] : num_keypoints) corrs_[id].resize(n);
  for (const auto& pair : pairs) {
    auto i1 = corrs_.find(pair.image_id1), i2 = corrs_.find(pair.image_id2);
    if (i1 == corrs_.end() || i2 == corrs_.end() || pair.image_id1 == pair.image_id2) {
      num_skipped_ += pair.inliers.size();
      continue;
    }
    int used = 0;
    for (const auto& m : pair.inliers) {
      if (m.idx1 >= i1->second.size() || m.idx2 >= i2->second.size()) {
        ++num_skipped_;
        continue;
      }
      i1->second[m.idx1].push_back({pair.image_id2, m.idx2});
      i2->second[m.idx2].push_back({pair.image_id1, m.idx1});
      ++used;
    }
    num_correspondences_ += used;
    if (used) {
      ++num_pairs_[pair.image_id1];
      ++num_pairs_[pair.image_id2];
    }
  }
  for (auto& [id, lists] : corrs_)
    for (auto& l : lists) {
      std::sort(l.begin(), l.end(), [](const core::TrackElement& a, const core::TrackElement& b) {
        return a.image_id != b.image_id ? a.image_id < b.image_id : a.point2d_idx < b.point2d_idx;
      });
      l.erase(std::unique(l.begin(), l.end()), l.end());
    }
}

const std::vector<core::TrackElement>& CorrespondenceGraph::Correspondences(uint32_t image_id, uint32_t kp) const {
  auto it = corrs_.find(image_id);
  if (it == corrs_.end() || kp >= it->second.size()) return kEmpty;
  return it->second[kp];
}

bool CorrespondenceGraph::IsTwoViewObservation(uint32_t image_id, uint32_t kp) const {
  const auto& corrs = Correspondences(image_id, kp);
  return corrs.size() == 1 && Correspondences(corrs[0].image_id, corrs[0].point2d_idx).size() == 1;
}

int CorrespondenceGraph::NumPairs(uint32_t image_id) const {
  auto it = num_pairs_.find(image_id);
  return it == num_pairs_.end() ? 0 : it->second;
}

int CorrespondenceGraph::NumObservedKeypoints(uint32_t image_id) const {
  auto it = corrs_.find(image_id);
  if (it == corrs_.end()) return 0;
  int n = 0;
  for (const auto& l : it->second) n += l.empty() ? 0 : 1;
  return n;
}

}  // namespace fmv3d::sfm
