#include "fmv3d/sfm/manual_registration.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/absolute_pose.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::sfm {

void ManualRegistrationOptions::Check() const {
  if (min_tie_points < 4) throw Error("sparse: --tie-min-points must be ≥ 4 (a pose needs 3 + 1 to check)");
  if (!(max_error_px > 0)) throw Error("sparse: the tie-point reprojection bound must be > 0");
  if (!(weight > 0)) throw Error("sparse: --tie-weight must be > 0");
}

namespace {

double PixelError(const core::Reconstruction& rec, const core::TrackElement& el, const Eigen::Vector3d& X) {
  const core::Image& im = rec.images.at(el.image_id);
  const Eigen::Vector3d xc = im.pose.Transform(X);
  if (xc.z() <= 0) return std::numeric_limits<double>::infinity();
  return (rec.cameras.at(im.camera_id).Project(xc) - im.points2d[el.point2d_idx]).norm();
}

// The model point a track's registered observations already belong to, or kNoPoint3D.
int64_t ExistingPoint(const core::Reconstruction& rec, const TieTrack& t) {
  for (const auto& el : t.observations) {
    const auto it = rec.images.find(el.image_id);
    if (it == rec.images.end() || el.point2d_idx >= it->second.point3d_ids.size()) continue;
    if (it->second.point3d_ids[el.point2d_idx] != core::kNoPoint3D) return it->second.point3d_ids[el.point2d_idx];
  }
  return core::kNoPoint3D;
}

// Adds every registered, not yet linked observation of the track to point pid (when it reprojects within bound).
void LinkObservations(core::Reconstruction* rec, const TieTrack& t, uint64_t pid, double max_error_px) {
  core::Point3D& p = rec->points.at(pid);
  for (const auto& el : t.observations) {
    auto it = rec->images.find(el.image_id);
    if (it == rec->images.end() || el.point2d_idx >= it->second.point3d_ids.size()) continue;
    if (it->second.point3d_ids[el.point2d_idx] != core::kNoPoint3D) continue;
    // One observation of a point per image.
    if (std::any_of(p.track.begin(), p.track.end(),
                    [&](const core::TrackElement& e) { return e.image_id == el.image_id; }))
      continue;
    if (PixelError(*rec, el, p.xyz) > max_error_px) continue;
    it->second.point3d_ids[el.point2d_idx] = static_cast<int64_t>(pid);
    p.track.push_back(el);
  }
}

// Triangulates a tie point from its registered observations and adds it; false when it cannot.
bool TriangulateTiePoint(core::Reconstruction* rec, const TieTrack& t, double max_error_px) {
  std::vector<core::Pose> poses;
  std::vector<Eigen::Vector2d> normalized;
  std::vector<core::TrackElement> els;
  std::set<uint32_t> seen;
  for (const auto& el : t.observations) {
    const auto it = rec->images.find(el.image_id);
    if (it == rec->images.end() || el.point2d_idx >= it->second.points2d.size() || !seen.insert(el.image_id).second)
      continue;
    const core::Camera& cam = rec->cameras.at(it->second.camera_id);
    poses.push_back(it->second.pose);
    normalized.push_back(cam.Unproject(it->second.points2d[el.point2d_idx]).head<2>());
    els.push_back(el);
  }
  if (poses.size() < 2) return false;
  Eigen::Vector3d X;
  if (!geometry::TriangulateDLT(poses, normalized, &X)) return false;
  geometry::RefinePoint(poses, normalized, &X, 10);
  for (const auto& el : els)
    if (PixelError(*rec, el, X) > max_error_px) return false;
  core::Point3D p;
  p.id = rec->points.empty() ? 1 : rec->points.rbegin()->first + 1;
  p.xyz = X;
  const uint64_t pid = p.id;
  rec->points[pid] = std::move(p);
  LinkObservations(rec, t, pid, max_error_px);
  if (rec->points.at(pid).track.size() < 2) {  // should not happen: every observation was checked above
    for (const auto& el : rec->points.at(pid).track)
      rec->images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    rec->points.erase(pid);
    return false;
  }
  return true;
}

}  // namespace

nlohmann::json ManualRegistrationResult::ToJson(const std::map<uint32_t, std::string>& names) const {
  auto name = [&](uint32_t id) {
    const auto it = names.find(id);
    return it == names.end() ? std::to_string(id) : it->second;
  };
  nlohmann::json reg = nlohmann::json::array(), failed = nlohmann::json::array(), ties = nlohmann::json::array();
  for (uint32_t id : registered) reg.push_back(name(id));
  for (const auto& [id, why] : still_failed) failed.push_back({{"image", name(id)}, {"reason", why}});
  for (const auto& t : tie_points)
    ties.push_back({{"id", t.id},
                    {"observations", t.observations},
                    {"in_registered_frames", t.in_model},
                    {"triangulated", t.in_point},
                    {"reprojection_px", t.reprojection_px}});
  return {{"registered_through_tie_points", reg},
          {"still_failed", failed},
          {"points_triangulated", points_triangulated},
          {"tie_points", ties}};
}

ManualRegistrationResult RegisterWithTiePoints(core::Reconstruction* rec, const std::vector<TieTrack>& tracks,
                                               const std::map<uint32_t, std::vector<Eigen::Vector2d>>& keypoints,
                                               const std::map<uint32_t, std::string>& names,
                                               const std::map<uint32_t, uint32_t>& image_cameras,
                                               const std::map<uint32_t, core::Camera>& cameras,
                                               const std::map<uint32_t, uint32_t>& manual_from,
                                               const ManualRegistrationOptions& o) {
  o.Check();
  ManualRegistrationResult result;
  if (rec->images.empty()) return result;
  std::set<uint32_t> candidates;
  for (const auto& t : tracks)
    for (const auto& el : t.observations)
      if (!rec->images.count(el.image_id) && keypoints.count(el.image_id)) candidates.insert(el.image_id);
  for (int round = 0; round < o.max_rounds; ++round) {
    // 1. Ground points of the tie points.
    for (const auto& t : tracks) {
      const int64_t pid = ExistingPoint(*rec, t);
      if (pid != core::kNoPoint3D)
        LinkObservations(rec, t, static_cast<uint64_t>(pid), o.max_error_px);
      else
        result.points_triangulated += TriangulateTiePoint(rec, t, o.max_error_px);
    }
    // 2. Frames outside the model.
    std::vector<uint32_t> added;
    for (uint32_t id : candidates) {
      if (rec->images.count(id)) continue;
      std::vector<Eigen::Vector2d> x2;
      std::vector<Eigen::Vector3d> x3;
      std::vector<std::pair<uint32_t, uint64_t>> links;  // (keypoint, point)
      for (const auto& t : tracks) {
        const int64_t pid = ExistingPoint(*rec, t);
        if (pid == core::kNoPoint3D) continue;
        for (const auto& el : t.observations)
          if (el.image_id == id) {
            x2.push_back(keypoints.at(id).at(el.point2d_idx));
            x3.push_back(rec->points.at(static_cast<uint64_t>(pid)).xyz);
            links.emplace_back(el.point2d_idx, static_cast<uint64_t>(pid));
            break;
          }
      }
      if (static_cast<int>(x2.size()) < o.min_tie_points) {
        result.still_failed[id] = fmt::format("{} tie points in the model, {} needed", x2.size(), o.min_tie_points);
        continue;
      }
      const uint32_t cam_id = image_cameras.at(id);
      const core::Camera& cam = rec->cameras.count(cam_id) ? rec->cameras.at(cam_id) : cameras.at(cam_id);
      geometry::AbsolutePoseOptions po;
      po.max_error_px = o.max_error_px;
      po.min_inliers = o.min_tie_points;
      po.min_inlier_ratio = 0.5;
      po.max_iterations = 2000;
      const auto pose = geometry::EstimateAbsolutePose(x2, x3, cam, po);
      if (!pose.success) {
        result.still_failed[id] = fmt::format("{} tie points in the model, but no pose fits {} of them within {} px",
                                              x2.size(), o.min_tie_points, o.max_error_px);
        continue;
      }
      if (!rec->cameras.count(cam_id)) rec->cameras[cam_id] = cam;
      core::Image im;
      im.id = id;
      im.camera_id = cam_id;
      im.name = names.count(id) ? names.at(id) : std::to_string(id);
      im.pose = pose.pose;
      im.points2d = keypoints.at(id);
      im.point3d_ids.assign(im.points2d.size(), core::kNoPoint3D);
      rec->images[id] = std::move(im);
      for (size_t k = 0; k < links.size(); ++k) {
        if (!pose.inlier_mask[k]) continue;
        core::Point3D& p = rec->points.at(links[k].second);
        rec->images.at(id).point3d_ids[links[k].first] = static_cast<int64_t>(p.id);
        p.track.push_back({id, links[k].first});
      }
      result.still_failed.erase(id);
      result.registered.push_back(id);
      added.push_back(id);
      spdlog::info("sparse: {} registered through {} tie points ({} inliers, {:.2f} px)", rec->images.at(id).name,
                   x2.size(), pose.num_inliers, pose.mean_inlier_error_px);
    }
    if (added.empty()) break;
    // 3. The whole model, intrinsics held, tie points weighted.
    BundleAdjustmentConfig config;
    for (const auto& [cid, c] : rec->cameras) config.constant_cameras.insert(cid);
    config.weighted_from = manual_from;
    config.observation_weight = o.weight;
    BundleAdjustmentOptions ba;
    ba.max_iterations = o.ba_max_iterations;
    ba.refine_focal = ba.refine_k1 = ba.refine_k2 = false;
    BundleAdjust(rec, config, ba);
  }
  // What became of each tie point.
  for (const auto& t : tracks) {
    ManualRegistrationResult::TieReport r;
    r.id = t.id;
    r.observations = static_cast<int>(t.observations.size());
    for (const auto& el : t.observations) r.in_model += rec->images.count(el.image_id) > 0;
    const int64_t pid = ExistingPoint(*rec, t);
    r.in_point = pid != core::kNoPoint3D;
    if (r.in_point) {
      double sse = 0;
      int n = 0;
      for (const auto& el : rec->points.at(static_cast<uint64_t>(pid)).track) {
        const double e = PixelError(*rec, el, rec->points.at(static_cast<uint64_t>(pid)).xyz);
        if (std::isfinite(e)) {
          sse += e * e;
          ++n;
        }
      }
      r.reprojection_px = n ? std::sqrt(sse / n) : 0.0;
    }
    result.tie_points.push_back(r);
  }
  UpdatePointErrors(rec);
  return result;
}

}  // namespace fmv3d::sfm
