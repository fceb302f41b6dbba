#include "fmv3d/sfm/triangulator.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/mapper_primitives.h"

namespace fmv3d::sfm {

namespace {
constexpr double kDeg = M_PI / 180.0;
}  // namespace

IncrementalTriangulator::IncrementalTriangulator(const CorrespondenceGraph& graph, core::Reconstruction* rec,
                                                 const TriangulatorOptions& options, KeypointColour colour)
    : graph_(graph), rec_(rec), options_(options), colour_(std::move(colour)) {
  if (!rec_->points.empty()) next_point_id_ = rec_->points.rbegin()->first + 1;
}

int64_t IncrementalTriangulator::CreatePoint(const std::vector<core::TrackElement>& obs) {
  const size_t n = obs.size();
  if (n < 2) return core::kNoPoint3D;
  std::vector<core::Pose> poses(n);
  std::vector<Eigen::Vector2d> xs(n), uvs(n);
  std::vector<Eigen::Vector3d> centres(n);
  std::vector<const core::Camera*> cams(n);
  for (size_t i = 0; i < n; ++i) {
    const auto& im = rec_->images.at(obs[i].image_id);
    cams[i] = &rec_->cameras.at(im.camera_id);
    poses[i] = im.pose;
    uvs[i] = im.points2d[obs[i].point2d_idx];
    xs[i] = cams[i]->Unproject(uvs[i]).head<2>();
    centres[i] = im.pose.Centre();
  }
  const double max_error = options_.max_error_px, min_angle = options_.min_angle_deg * kDeg;
  auto inliers_of = [&](const Eigen::Vector3d& X, std::vector<size_t>* in) {
    in->clear();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d xc = poses[i].Transform(X);
      if (xc.z() <= 0) continue;
      if ((cams[i]->Project(xc) - uvs[i]).norm() <= max_error) in->push_back(i);
    }
  };
  // Small RANSAC over observation pairs: the correspondences can contain a wrong match.
  std::vector<size_t> best_in;
  const size_t m = std::min<size_t>(n, 10);
  for (size_t i = 0; i < m && best_in.size() < n; ++i)
    for (size_t j = i + 1; j < m; ++j) {
      Eigen::Vector3d X;
      if (!geometry::TriangulateDLT({poses[i], poses[j]}, {xs[i], xs[j]}, &X)) continue;
      if (geometry::TriangulationAngle(centres[i], centres[j], X) < min_angle) continue;
      std::vector<size_t> in;
      inliers_of(X, &in);
      if (in.size() > best_in.size()) best_in = in;
      if (best_in.size() == n) break;
    }
  if (best_in.size() < 2) return core::kNoPoint3D;
  std::vector<core::Pose> ps;
  std::vector<Eigen::Vector2d> xx;
  for (size_t i : best_in) {
    ps.push_back(poses[i]);
    xx.push_back(xs[i]);
  }
  Eigen::Vector3d X;
  if (!geometry::TriangulateDLT(ps, xx, &X)) return core::kNoPoint3D;
  geometry::RefinePoint(ps, xx, &X);
  std::vector<size_t> in;
  inliers_of(X, &in);
  if (in.size() < 2) return core::kNoPoint3D;
  std::vector<Eigen::Vector3d> cs;
  for (size_t i : in) cs.push_back(centres[i]);
  if (geometry::MaxTriangulationAngle(cs, X) < min_angle) return core::kNoPoint3D;
  const uint64_t pid = next_point_id_++;
  core::Point3D p;
  p.id = pid;
  p.xyz = X;
  if (colour_) colour_(obs[in[0]].image_id, obs[in[0]].point2d_idx, &p.rgb);
  rec_->points[pid] = p;
  for (size_t i : in) AddObservation(rec_, pid, obs[i].image_id, obs[i].point2d_idx);
  return static_cast<int64_t>(pid);
}

void IncrementalTriangulator::TriangulateKeypoint(uint32_t image_id, uint32_t kp) {
  const auto& corrs = graph_.Correspondences(image_id, kp);
  if (corrs.empty()) return;
  if (rec_->images.at(image_id).point3d_ids[kp] != core::kNoPoint3D) return;
  // Continuation: join the best-fitting existing point among the correspondences.
  int64_t best_pid = core::kNoPoint3D;
  double best_err = options_.max_error_px;
  for (const auto& c : corrs) {
    const int64_t pid = PointOf(*rec_, c);
    if (pid == core::kNoPoint3D || pid == best_pid) continue;
    const double e = ObservationError(*rec_, image_id, kp, rec_->points.at(static_cast<uint64_t>(pid)).xyz);
    if (e <= best_err && !PointHasImage(*rec_, static_cast<uint64_t>(pid), image_id)) {
      best_err = e;
      best_pid = pid;
    }
  }
  if (best_pid != core::kNoPoint3D) {
    AddObservation(rec_, static_cast<uint64_t>(best_pid), image_id, kp);
    return;
  }
  // Creation: this keypoint and its registered, untriangulated correspondences (one per image).
  if (options_.ignore_two_view_tracks && graph_.IsTwoViewObservation(image_id, kp)) return;
  std::vector<core::TrackElement> obs = {{image_id, kp}};
  std::set<uint32_t> seen = {image_id};
  for (const auto& c : corrs)
    if (rec_->images.count(c.image_id) && PointOf(*rec_, c) == core::kNoPoint3D && seen.insert(c.image_id).second)
      obs.push_back(c);
  if (obs.size() >= 2) CreatePoint(obs);
}

int IncrementalTriangulator::CompletePoint(uint64_t pid) {
  int added = 0;
  // Breadth-first over the correspondence graph: an added observation can bring further ones.
  for (size_t k = 0; k < rec_->points.at(pid).track.size(); ++k) {
    const core::TrackElement el = rec_->points.at(pid).track[k];
    for (const auto& c : graph_.Correspondences(el.image_id, el.point2d_idx)) {
      if (!rec_->images.count(c.image_id) || PointOf(*rec_, c) != core::kNoPoint3D ||
          PointHasImage(*rec_, pid, c.image_id))
        continue;
      if (ObservationError(*rec_, c.image_id, c.point2d_idx, rec_->points.at(pid).xyz) <= options_.max_error_px) {
        AddObservation(rec_, pid, c.image_id, c.point2d_idx);
        ++added;
      }
    }
  }
  return added;
}

int IncrementalTriangulator::MergePoint(uint64_t pid) {
  int merged = 0;
  for (size_t k = 0; rec_->points.count(pid) && k < rec_->points.at(pid).track.size(); ++k) {
    const core::TrackElement el = rec_->points.at(pid).track[k];
    for (const auto& c : graph_.Correspondences(el.image_id, el.point2d_idx)) {
      const int64_t other = PointOf(*rec_, c);
      if (other == core::kNoPoint3D || static_cast<uint64_t>(other) == pid) continue;
      auto& P = rec_->points.at(pid);
      auto& Q = rec_->points.at(static_cast<uint64_t>(other));
      bool ok = true;
      for (const auto& q : Q.track) ok = ok && !PointHasImage(*rec_, pid, q.image_id);
      if (!ok) continue;
      // Candidate position: the better-supported point's; every observation of both must agree with it.
      const Eigen::Vector3d X = P.track.size() >= Q.track.size() ? P.xyz : Q.xyz;
      for (const auto& o : P.track)
        ok = ok && ObservationError(*rec_, o.image_id, o.point2d_idx, X) <= options_.max_error_px;
      for (const auto& o : Q.track)
        ok = ok && ObservationError(*rec_, o.image_id, o.point2d_idx, X) <= options_.max_error_px;
      if (!ok) continue;
      const auto qtrack = Q.track;
      DeletePoint(rec_, static_cast<uint64_t>(other));
      rec_->points.at(pid).xyz = X;
      for (const auto& o : qtrack) AddObservation(rec_, pid, o.image_id, o.point2d_idx);
      ++merged;
    }
  }
  return merged;
}

int IncrementalTriangulator::TriangulateImage(uint32_t image_id) {
  const size_t before = rec_->points.size();
  const auto& im = rec_->images.at(image_id);
  for (uint32_t kp = 0; kp < im.points2d.size(); ++kp) TriangulateKeypoint(image_id, kp);
  std::set<uint64_t> pts;
  for (int64_t pid : rec_->images.at(image_id).point3d_ids)
    if (pid != core::kNoPoint3D) pts.insert(static_cast<uint64_t>(pid));
  for (uint64_t pid : pts) {
    if (!rec_->points.count(pid)) continue;
    CompletePoint(pid);
    MergePoint(pid);
  }
  return static_cast<int>(rec_->points.size()) - static_cast<int>(before);
}

int IncrementalTriangulator::Retriangulate() {
  const size_t before = rec_->points.size();
  std::vector<uint32_t> ids;
  for (const auto& [id, im] : rec_->images) ids.push_back(id);
  for (uint32_t id : ids)
    for (uint32_t kp = 0; kp < rec_->images.at(id).points2d.size(); ++kp) TriangulateKeypoint(id, kp);
  std::vector<uint64_t> pids;
  for (const auto& [pid, p] : rec_->points) pids.push_back(pid);
  int changed = 0;
  for (uint64_t pid : pids) {
    if (!rec_->points.count(pid)) continue;
    changed += CompletePoint(pid);
    changed += MergePoint(pid);
  }
  return changed + static_cast<int>(rec_->points.size()) - static_cast<int>(before);
}

}  // namespace fmv3d::sfm
