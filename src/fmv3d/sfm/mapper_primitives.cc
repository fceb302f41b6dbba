#include "fmv3d/sfm/mapper_primitives.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>
#include <vector>

#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::sfm {

int64_t PointOf(const core::Reconstruction& rec, const core::TrackElement& el) {
  auto it = rec.images.find(el.image_id);
  return it == rec.images.end() ? core::kNoPoint3D : it->second.point3d_ids[el.point2d_idx];
}

bool PointHasImage(const core::Reconstruction& rec, uint64_t point_id, uint32_t image_id) {
  for (const auto& el : rec.points.at(point_id).track)
    if (el.image_id == image_id) return true;
  return false;
}

void AddObservation(core::Reconstruction* rec, uint64_t point_id, uint32_t image_id, uint32_t kp) {
  auto& im = rec->images.at(image_id);
  if (im.point3d_ids[kp] != core::kNoPoint3D) return;
  im.point3d_ids[kp] = static_cast<int64_t>(point_id);
  rec->points.at(point_id).track.push_back({image_id, kp});
}

void DeletePoint(core::Reconstruction* rec, uint64_t point_id) {
  auto it = rec->points.find(point_id);
  if (it == rec->points.end()) return;
  for (const auto& el : it->second.track) rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
  rec->points.erase(it);
}

std::vector<uint32_t> ImagesSharingMostPoints(const core::Reconstruction& rec, uint32_t image_id, int k) {
  std::map<uint32_t, int> shared;
  for (int64_t pid : rec.images.at(image_id).point3d_ids) {
    if (pid == core::kNoPoint3D) continue;
    for (const auto& el : rec.points.at(static_cast<uint64_t>(pid)).track)
      if (el.image_id != image_id) ++shared[el.image_id];
  }
  std::vector<std::pair<int, uint32_t>> order;
  order.reserve(shared.size());
  for (const auto& [id, n] : shared) order.emplace_back(-n, id);
  std::sort(order.begin(), order.end());
  std::vector<uint32_t> out;
  for (size_t i = 0; i < order.size() && static_cast<int>(i) < k; ++i) out.push_back(order[i].second);
  return out;
}

void DetachImage(core::Reconstruction* rec, uint32_t image_id) {
  auto& im = rec->images.at(image_id);
  for (int64_t& point_of_kp : im.point3d_ids) {
    const int64_t pid = point_of_kp;
    if (pid == core::kNoPoint3D) continue;
    auto& track = rec->points.at(static_cast<uint64_t>(pid)).track;
    track.erase(std::remove_if(track.begin(), track.end(),
                               [&](const core::TrackElement& el) { return el.image_id == image_id; }),
                track.end());
    point_of_kp = core::kNoPoint3D;
    if (track.size() < 2) DeletePoint(rec, static_cast<uint64_t>(pid));
  }
}

Correspondences2D3D FindCorrespondences2D3D(const core::Reconstruction& rec, const CorrespondenceGraph& graph,
                                            uint32_t image_id, const std::vector<Eigen::Vector2d>& keypoints) {
  Correspondences2D3D out;
  for (uint32_t kp = 0; kp < keypoints.size(); ++kp) {
    std::vector<int64_t> seen;
    for (const auto& c : graph.Correspondences(image_id, kp)) {
      const int64_t pid = PointOf(rec, c);
      if (pid == core::kNoPoint3D || std::find(seen.begin(), seen.end(), pid) != seen.end()) continue;
      seen.push_back(pid);
      out.points2d.push_back(keypoints[kp]);
      out.points3d.push_back(rec.points.at(static_cast<uint64_t>(pid)).xyz);
      out.keypoint_point.emplace_back(kp, static_cast<uint64_t>(pid));
    }
  }
  return out;
}

int CountVisiblePoints(const core::Reconstruction& rec, const CorrespondenceGraph& graph, uint32_t image_id,
                       const std::vector<Eigen::Vector2d>& keypoints, int width, int height, double* score) {
  constexpr int kLevels = 3;
  std::set<int> cells[kLevels];
  int count = 0;
  for (uint32_t kp = 0; kp < keypoints.size(); ++kp) {
    bool seen = false;
    for (const auto& c : graph.Correspondences(image_id, kp))
      if (PointOf(rec, c) != core::kNoPoint3D) {
        seen = true;
        break;
      }
    if (!seen) continue;
    ++count;
    for (int l = 0; l < kLevels; ++l) {
      const int g = 2 << l;  // 2, 4, 8 cells per side
      const int cx = std::clamp(static_cast<int>(keypoints[kp].x() / std::max(1, width) * g), 0, g - 1);
      const int cy = std::clamp(static_cast<int>(keypoints[kp].y() / std::max(1, height) * g), 0, g - 1);
      cells[l].insert(cy * g + cx);
    }
  }
  if (score) {
    *score = 0;
    for (int l = 0; l < kLevels; ++l) *score += static_cast<double>(cells[l].size()) * (2 << l);
  }
  return count;
}

int FilterPoints(core::Reconstruction* rec, const std::set<uint64_t>* subset, const PointFilterOptions& options) {
  constexpr double kDeg = M_PI / 180.0;
  std::vector<uint64_t> ids;
  if (subset)
    ids.assign(subset->begin(), subset->end());
  else
    for (const auto& [pid, p] : rec->points) ids.push_back(pid);
  int removed = 0;
  for (uint64_t pid : ids) {
    auto it = rec->points.find(pid);
    if (it == rec->points.end()) continue;
    auto& p = it->second;
    std::vector<core::TrackElement> keep;
    for (const auto& el : p.track) {
      if (ObservationError(*rec, el.image_id, el.point2d_idx, p.xyz) <= options.max_error_px)
        keep.push_back(el);
      else
        rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    }
    p.track = keep;
    bool drop = p.track.size() < 2;
    if (!drop) {
      std::vector<Eigen::Vector3d> cs;
      for (const auto& el : p.track) cs.push_back(rec->images.at(el.image_id).pose.Centre());
      drop = geometry::MaxTriangulationAngle(cs, p.xyz) < options.min_angle_deg * kDeg;
    }
    if (drop) {
      DeletePoint(rec, pid);
      ++removed;
    }
  }
  return removed;
}

}  // namespace fmv3d::sfm
