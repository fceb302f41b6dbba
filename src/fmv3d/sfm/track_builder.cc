#include "fmv3d/sfm/track_builder.h"

#include <algorithm>
#include <numeric>
#include <set>

namespace fmv3d::sfm {

namespace {

// Union–find over (image, keypoint) nodes; each root keeps the sorted images of its set, so that a union joining
// two sets seen in a common image is refused.
class DisjointTracks {
 public:
  explicit DisjointTracks(size_t n) : parent_(n), images_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  void Init(size_t node, uint32_t image_id) { images_[node] = {image_id}; }
  size_t Find(size_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  // False on a conflict (the sets share an image): nothing is joined.
  bool Union(size_t a, size_t b) {
    a = Find(a);
    b = Find(b);
    if (a == b) return true;
    auto &ia = images_[a], &ib = images_[b];
    std::vector<uint32_t> merged;
    merged.reserve(ia.size() + ib.size());
    std::set_union(ia.begin(), ia.end(), ib.begin(), ib.end(), std::back_inserter(merged));
    if (merged.size() != ia.size() + ib.size()) return false;
    if (ia.size() < ib.size()) std::swap(a, b);
    parent_[b] = a;
    images_[a] = std::move(merged);
    images_[b].clear();
    return true;
  }

 private:
  std::vector<size_t> parent_;
  std::vector<std::vector<uint32_t>> images_;
};

}  // namespace

double TrackSet::MeanLength() const {
  size_t n = 0;
  for (const auto& t : tracks) n += t.size();
  return tracks.empty() ? 0 : static_cast<double>(n) / tracks.size();
}

double TrackSet::MeanLengthMultiView() const {
  size_t n = 0, m = 0;
  for (const auto& t : tracks)
    if (t.size() >= 3) {
      n += t.size();
      ++m;
    }
  return m ? static_cast<double>(n) / m : 0;
}

TrackSet BuildTracks(const std::map<uint32_t, size_t>& num_keypoints,
                     const std::vector<features::VerifiedPair>& pairs) {
  std::map<uint32_t, size_t> offset;
  size_t total = 0;
  for (const auto& [id, n] : num_keypoints) {
    offset[id] = total;
    total += n;
  }
  DisjointTracks sets(total);
  std::vector<core::TrackElement> element(total);
  for (const auto& [id, n] : num_keypoints)
    for (size_t k = 0; k < n; ++k) {
      sets.Init(offset[id] + k, id);
      element[offset[id] + k] = {id, static_cast<uint32_t>(k)};
    }
  std::vector<const features::VerifiedPair*> order;
  for (const auto& p : pairs)
    if (p.image_id1 != p.image_id2 && num_keypoints.count(p.image_id1) && num_keypoints.count(p.image_id2))
      order.push_back(&p);
  // Strongest pair first; ties in input order (deterministic).
  std::stable_sort(order.begin(), order.end(), [](const features::VerifiedPair* a, const features::VerifiedPair* b) {
    return a->inliers.size() > b->inliers.size();
  });
  TrackSet out;
  std::vector<bool> linked(total, false);
  for (const features::VerifiedPair* p : order) {
    const size_t n1 = num_keypoints.at(p->image_id1), n2 = num_keypoints.at(p->image_id2);
    for (const auto& m : p->inliers) {
      if (m.idx1 >= n1 || m.idx2 >= n2) continue;
      const size_t a = offset[p->image_id1] + m.idx1, b = offset[p->image_id2] + m.idx2;
      if (sets.Find(a) == sets.Find(b)) continue;  // already linked (a duplicate match or a closed cycle)
      if (sets.Union(a, b)) {
        ++out.num_links;
        linked[a] = linked[b] = true;
      } else {
        ++out.num_conflicts;
      }
    }
  }
  std::map<size_t, size_t> track_of_root;
  for (size_t x = 0; x < total; ++x) {
    if (!linked[x]) continue;
    auto [it, added] = track_of_root.emplace(sets.Find(x), out.tracks.size());
    if (added) out.tracks.emplace_back();
    out.tracks[it->second].push_back(element[x]);
  }
  for (auto& t : out.tracks)
    std::sort(t.begin(), t.end(),
              [](const core::TrackElement& a, const core::TrackElement& b) { return a.image_id < b.image_id; });
  return out;
}

TrackCoverage MeasureTrackCoverage(const TrackSet& tracks, const core::Reconstruction& rec) {
  TrackCoverage c;
  c.points = rec.points.size();
  for (const auto& [pid, p] : rec.points) c.observations += p.track.size();
  for (const auto& t : tracks.tracks) {
    std::set<int64_t> points;
    size_t held = 0;
    for (const auto& el : t) {
      auto im = rec.images.find(el.image_id);
      if (im == rec.images.end() || el.point2d_idx >= im->second.point3d_ids.size()) continue;
      const int64_t pid = im->second.point3d_ids[el.point2d_idx];
      if (pid == core::kNoPoint3D) continue;
      points.insert(pid);
      ++held;
    }
    if (points.empty()) continue;
    ++c.tracks_touched;
    c.keypoints_of_touched_tracks += t.size();
    c.held_of_touched_tracks += held;
    c.tracks_split += points.size() > 1;
  }
  return c;
}

}  // namespace fmv3d::sfm
