#include "fmv3d/sfm/relocalise.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/features/matcher.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/mapper_primitives.h"

namespace fmv3d::sfm {

namespace {

constexpr double kDeg = M_PI / 180.0;
// Quantised descriptors are unit vectors times 512 (features/sift.h): unrelated ones lie ~1.0–1.3 apart, true
// matches well below 0.6. Guided candidates farther than this are never matches, however alone they are.
constexpr int kMaxGuidedDistanceSq = static_cast<int>(0.6 * 512 * 0.6 * 512);

int DistanceSq(const features::Descriptors& a, int i, const features::Descriptors& b, int j) {
  const uint8_t* pa = a.data() + static_cast<size_t>(i) * 128;
  const uint8_t* pb = b.data() + static_cast<size_t>(j) * 128;
  int s = 0;
  for (int k = 0; k < 128; ++k) {
    const int d = int(pa[k]) - int(pb[k]);
    s += d * d;
  }
  return s;
}

// Points of the model as rows of a descriptor bank: the medoid of (up to 8 of) each track's descriptors.
void BuildPointBank(const core::Reconstruction& rec, const std::map<uint32_t, const features::FeatureSet*>& feats,
                    features::Descriptors* bank, std::vector<uint64_t>* point_ids) {
  std::vector<const core::Point3D*> pts;
  for (const auto& [id, p] : rec.points)
    if (!p.track.empty()) pts.push_back(&p);
  bank->resize(static_cast<Eigen::Index>(pts.size()), 128);
  point_ids->resize(pts.size());
  tbb::parallel_for(size_t{0}, pts.size(), [&](size_t r) {
    const auto& track = pts[r]->track;
    const size_t m = std::min<size_t>(track.size(), 8);
    size_t best = 0;
    long best_sum = std::numeric_limits<long>::max();
    for (size_t a = 0; a < m; ++a) {
      long sum = 0;
      const auto& da = feats.at(track[a].image_id)->descriptors;
      for (size_t b = 0; b < m; ++b)
        if (a != b)
          sum += DistanceSq(da, static_cast<int>(track[a].point2d_idx), feats.at(track[b].image_id)->descriptors,
                            static_cast<int>(track[b].point2d_idx));
      if (sum < best_sum) best_sum = sum, best = a;
    }
    const auto& src = feats.at(track[best].image_id)->descriptors;
    bank->row(static_cast<Eigen::Index>(r)) = src.row(track[best].point2d_idx);
    (*point_ids)[r] = pts[r]->id;
  });
}

double ReprojectionError(const core::Reconstruction& rec, const core::Image& im, const Eigen::Vector2d& uv,
                         const Eigen::Vector3d& X) {
  const Eigen::Vector3d xc = im.pose.Transform(X);
  if (xc.z() <= 0) return std::numeric_limits<double>::infinity();
  return (rec.cameras.at(im.camera_id).Project(xc) - uv).norm();
}

// Depth range of the points an image observes (5th–95th percentile, widened), for the guided search.
bool DepthRange(const core::Reconstruction& rec, uint32_t image_id, double* lo, double* hi) {
  std::vector<double> z;
  const auto& im = rec.images.at(image_id);
  for (int64_t pid : im.point3d_ids)
    if (pid != core::kNoPoint3D) z.push_back(im.pose.Transform(rec.points.at(static_cast<uint64_t>(pid)).xyz).z());
  if (z.size() < 5) return false;
  std::sort(z.begin(), z.end());
  *lo = 0.7 * z[z.size() / 20];
  *hi = 1.4 * z[z.size() - 1 - z.size() / 20];
  return *lo > 0 && *hi > *lo;
}

int RemoveObservation(core::Reconstruction* rec, uint64_t pid, uint32_t image_id) {
  auto& p = rec->points.at(pid);
  int removed = 0;
  for (auto it = p.track.begin(); it != p.track.end();) {
    if (it->image_id == image_id) {
      rec->images.at(image_id).point3d_ids[it->point2d_idx] = core::kNoPoint3D;
      it = p.track.erase(it);
      ++removed;
    } else {
      ++it;
    }
  }
  return removed;
}

// Drops observations above max_error_px and points left with fewer than two; returns observations dropped.
int FilterObservations(core::Reconstruction* rec, double max_error_px) {
  int dropped = 0;
  std::vector<uint64_t> empty;
  for (auto& [pid, p] : rec->points) {
    for (auto it = p.track.begin(); it != p.track.end();) {
      const auto& im = rec->images.at(it->image_id);
      if (ReprojectionError(*rec, im, im.points2d[it->point2d_idx], p.xyz) > max_error_px) {
        rec->images.at(it->image_id).point3d_ids[it->point2d_idx] = core::kNoPoint3D;
        it = p.track.erase(it);
        ++dropped;
      } else {
        ++it;
      }
    }
    if (p.track.size() < 2) empty.push_back(pid);
  }
  for (uint64_t pid : empty) DeletePoint(rec, pid);
  return dropped;
}

}  // namespace

void RelocaliseOptions::Check() const {
  pose.Check();
  if (!(ratio > 0 && ratio <= 1)) throw Error("relocalise: ratio must be in (0, 1]");
  if (!(guided_ratio > 0 && guided_ratio <= 1)) throw Error("relocalise: guided ratio must be in (0, 1]");
  if (guided_neighbours < 0) throw Error("relocalise: guided neighbours must be >= 0");
  if (!(guided_max_epipolar_px > 0)) throw Error("relocalise: guided epipolar distance must be > 0");
  if (!(tri_min_angle_deg >= 0) || !(tri_max_error_px > 0) || !(filter_max_error_px > 0))
    throw Error("relocalise: triangulation bounds must be positive");
  if (max_rounds < 1) throw Error("relocalise: max rounds must be >= 1");
}

std::vector<features::FeatureMatch> GuidedMatches(const core::Reconstruction& rec, uint32_t image1, uint32_t image2,
                                                  const features::FeatureSet& f1, const features::FeatureSet& f2,
                                                  double depth_min, double depth_max, double max_epipolar_px,
                                                  double ratio) {
  const auto& im1 = rec.images.at(image1);
  const auto& im2 = rec.images.at(image2);
  const auto& cam1 = rec.cameras.at(im1.camera_id);
  const auto& cam2 = rec.cameras.at(im2.camera_id);
  // Untriangulated keypoints of image 2 in a grid of cells.
  constexpr double kCell = 16;
  const int gw = std::max(1, static_cast<int>(std::ceil(cam2.width / kCell)));
  const int gh = std::max(1, static_cast<int>(std::ceil(cam2.height / kCell)));
  std::vector<std::vector<int>> grid(static_cast<size_t>(gw) * gh);
  std::vector<Eigen::Vector2d> n2(f2.keypoints.size());
  for (size_t b = 0; b < f2.keypoints.size(); ++b) {
    if (im2.point3d_ids[b] != core::kNoPoint3D) continue;
    const int cx = std::clamp(static_cast<int>(f2.keypoints[b].x / kCell), 0, gw - 1);
    const int cy = std::clamp(static_cast<int>(f2.keypoints[b].y / kCell), 0, gh - 1);
    grid[static_cast<size_t>(cy) * gw + cx].push_back(static_cast<int>(b));
    n2[b] = cam2.Unproject(Eigen::Vector2d(f2.keypoints[b].x, f2.keypoints[b].y)).head<2>();
  }
  // Relative pose 1 → 2 and the essential matrix on normalised coordinates: x2ᵀ E x1 = 0.
  const Eigen::Matrix3d R1 = im1.pose.R(), R2 = im2.pose.R();
  const Eigen::Matrix3d R = R2 * R1.transpose();
  const Eigen::Vector3d t = im2.pose.t - R * im1.pose.t;
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  const Eigen::Matrix3d E = tx * R;
  const double f2px = cam2.fx();
  const Eigen::Vector3d C1 = im1.pose.Centre();
  constexpr int kDepthSamples = 12;
  std::vector<std::pair<int, std::pair<int, int>>> best_for_b;  // (distance, (a, b))
  std::vector<features::FeatureMatch> raw;
  std::vector<int> raw_dist;
  std::vector<char> mark(grid.size(), 0);
  std::vector<int> touched;
  for (size_t a = 0; a < f1.keypoints.size(); ++a) {
    if (im1.point3d_ids[a] != core::kNoPoint3D) continue;
    const Eigen::Vector3d ray_cam = cam1.Unproject(Eigen::Vector2d(f1.keypoints[a].x, f1.keypoints[a].y));
    const Eigen::Vector3d ray = R1.transpose() * ray_cam;  // world direction at unit camera-1 depth
    // The segment in image 2: projections at depths spaced evenly in inverse depth.
    std::vector<Eigen::Vector2d> poly;
    for (int s = 0; s < kDepthSamples; ++s) {
      const double w = static_cast<double>(s) / (kDepthSamples - 1);
      const double d = 1.0 / ((1 - w) / depth_min + w / depth_max);
      const Eigen::Vector3d xc = im2.pose.Transform(C1 + d * ray);
      if (xc.z() <= 0) continue;
      poly.push_back(cam2.Project(xc));
    }
    if (poly.empty()) continue;
    touched.clear();
    auto touch = [&](const Eigen::Vector2d& p) {
      const int cx = static_cast<int>(std::floor(p.x() / kCell)), cy = static_cast<int>(std::floor(p.y() / kCell));
      for (int y = cy - 1; y <= cy + 1; ++y)
        for (int x = cx - 1; x <= cx + 1; ++x) {
          if (x < 0 || y < 0 || x >= gw || y >= gh) continue;
          const int c = y * gw + x;
          if (!mark[c]) mark[c] = 1, touched.push_back(c);
        }
    };
    touch(poly[0]);
    for (size_t s = 1; s < poly.size(); ++s) {
      const double len = (poly[s] - poly[s - 1]).norm();
      if (!std::isfinite(len) || len > 4 * (cam2.width + cam2.height)) continue;
      const int steps = std::max(1, static_cast<int>(std::ceil(len / (0.5 * kCell))));
      for (int k = 1; k <= steps; ++k) touch(poly[s - 1] + (poly[s] - poly[s - 1]) * (double(k) / steps));
    }
    const Eigen::Vector3d line = E * Eigen::Vector3d(ray_cam.x() / ray_cam.z(), ray_cam.y() / ray_cam.z(), 1);
    const double ln = line.head<2>().norm();
    int d1 = std::numeric_limits<int>::max(), d2 = std::numeric_limits<int>::max(), b1 = -1;
    for (int c : touched) {
      mark[c] = 0;
      if (ln <= 0) continue;
      for (int b : grid[c]) {
        const double dist_px = std::abs(line.dot(Eigen::Vector3d(n2[b].x(), n2[b].y(), 1))) / ln * f2px;
        if (dist_px > max_epipolar_px) continue;
        const int d = DistanceSq(f1.descriptors, static_cast<int>(a), f2.descriptors, b);
        if (d < d1) {
          d2 = d1, d1 = d, b1 = b;
        } else if (d < d2) {
          d2 = d;
        }
      }
    }
    if (b1 < 0 || d1 > kMaxGuidedDistanceSq) continue;
    if (d2 != std::numeric_limits<int>::max() && !(std::sqrt(double(d1)) < ratio * std::sqrt(double(d2)))) continue;
    raw.push_back({static_cast<uint32_t>(a), static_cast<uint32_t>(b1)});
    raw_dist.push_back(d1);
  }
  // One match per keypoint of image 2: the closest descriptor wins.
  std::map<uint32_t, size_t> by_b;
  for (size_t i = 0; i < raw.size(); ++i) {
    auto it = by_b.find(raw[i].idx2);
    if (it == by_b.end() || raw_dist[i] < raw_dist[it->second]) by_b[raw[i].idx2] = i;
  }
  std::vector<features::FeatureMatch> out;
  out.reserve(by_b.size());
  for (const auto& [b, i] : by_b) out.push_back(raw[i]);
  std::sort(out.begin(), out.end(), [](const auto& x, const auto& y) { return x.idx1 < y.idx1; });
  return out;
}

namespace {

// Rejects candidates without features or camera and model images whose features are not their 2D points.
void CheckRelocaliseInputs(const core::Reconstruction& rec, const std::vector<RelocaliseCandidate>& candidates,
                           const std::map<uint32_t, const features::FeatureSet*>& feats,
                           const std::map<uint32_t, core::Camera>& cameras) {
  for (const auto& c : candidates) {
    if (!feats.count(c.image_id)) throw Error("relocalise: no features for image " + c.name);
    if (!rec.cameras.count(c.camera_id) && !cameras.count(c.camera_id))
      throw Error("relocalise: image " + c.name + " refers to unknown camera " + std::to_string(c.camera_id));
  }
  for (const auto& [id, im] : rec.images) {
    const auto it = feats.find(id);
    if (it == feats.end()) throw Error("relocalise: no features for model image " + im.name);
    if (it->second->keypoints.size() != im.points2d.size())
      throw Error("relocalise: features of " + im.name + " do not match the model's 2D points");
  }
}

// The model's points as one descriptor bank (BuildPointBank), matched against by every candidate of a round.
struct RelocalisePointBank {
  features::Descriptors descriptors;
  std::vector<uint64_t> point_ids;  // per row
};

// One candidate's absolute pose against the model.
struct RelocaliseAttempt {
  geometry::AbsolutePoseResult pose;
  std::vector<std::pair<uint32_t, uint64_t>> matches;  // (keypoint, point id)
  std::string why;                                     // why it failed (empty on success)
};

RelocaliseAttempt AttemptRelocalisation(const core::Reconstruction& rec, const RelocaliseCandidate& c,
                                        const features::FeatureSet& f, const RelocalisePointBank& bank,
                                        features::ImageDescriptors& bank_desc, const core::Camera& cam,
                                        const RelocaliseOptions& o) {
  RelocaliseAttempt at;
  if (f.keypoints.empty()) {
    at.why = "no features";
    return at;
  }
  features::MatchOptions mo;
  mo.ratio = o.ratio;
  mo.mutual = false;
  features::ImageDescriptors d(f.descriptors, c.image_id);
  const auto m = features::MatchDescriptors(d, bank_desc, mo);
  std::vector<Eigen::Vector2d> p2;
  std::vector<Eigen::Vector3d> p3;
  for (const auto& fm : m) {
    const uint64_t pid = bank.point_ids[fm.idx2];
    at.matches.emplace_back(fm.idx1, pid);
    p2.emplace_back(f.keypoints[fm.idx1].x, f.keypoints[fm.idx1].y);
    p3.push_back(rec.points.at(pid).xyz);
  }
  if (static_cast<int>(p2.size()) < o.pose.min_inliers) {
    at.why =
        std::to_string(p2.size()) + " 2D-3D matches with the model (" + std::to_string(o.pose.min_inliers) + " needed)";
    return at;
  }
  at.pose = geometry::EstimateAbsolutePose(p2, p3, cam, o.pose);
  if (!at.pose.success)
    at.why = "absolute pose failed on " + std::to_string(p2.size()) + " 2D-3D matches (" +
             std::to_string(at.pose.num_inliers) + " inliers)";
  return at;
}

// Adds a registered candidate to the model at its pose, observing each inlier point once (with the keypoint
// that reprojects best); returns the observations added.
int AddRelocalisedImage(core::Reconstruction* rec, const RelocaliseCandidate& c, const features::FeatureSet& f,
                        const RelocaliseAttempt& at, const core::Camera& cam, const RelocaliseOptions& o) {
  if (!rec->cameras.count(c.camera_id)) rec->cameras[c.camera_id] = cam;
  core::Image im;
  im.id = c.image_id;
  im.camera_id = c.camera_id;
  im.name = c.name;
  im.pose = at.pose.pose;
  for (const auto& kp : f.keypoints) im.points2d.emplace_back(kp.x, kp.y);
  im.point3d_ids.assign(im.points2d.size(), core::kNoPoint3D);
  rec->images[c.image_id] = im;
  std::map<uint64_t, std::pair<double, uint32_t>> best;
  const auto& stored = rec->images.at(c.image_id);
  for (size_t m = 0; m < at.matches.size(); ++m) {
    if (!at.pose.inlier_mask[m]) continue;
    const auto [kp, pid] = at.matches[m];
    const double e = ReprojectionError(*rec, stored, stored.points2d[kp], rec->points.at(pid).xyz);
    if (e > o.tri_max_error_px) continue;
    auto it = best.find(pid);
    if (it == best.end() || e < it->second.first) best[pid] = {e, kp};
  }
  for (const auto& [pid, ekp] : best) {
    rec->images.at(c.image_id).point3d_ids[ekp.second] = static_cast<int64_t>(pid);
    rec->points.at(pid).track.push_back({c.image_id, ekp.second});
  }
  return static_cast<int>(best.size());
}

// Guided matching of a new image with its registered neighbours, then two-view triangulation of the matches
// whose keypoints are both free (angle and reprojection checks). Returns the points added.
int TriangulateWithNeighbours(core::Reconstruction* rec, uint32_t id,
                              const std::map<uint32_t, const features::FeatureSet*>& feats, const RelocaliseOptions& o,
                              uint64_t* next_pid) {
  double lo = 0, hi = 0;
  if (!DepthRange(*rec, id, &lo, &hi)) return 0;
  int added = 0;
  for (uint32_t nb : ImagesSharingMostPoints(*rec, id, o.guided_neighbours)) {
    const auto matches =
        GuidedMatches(*rec, id, nb, *feats.at(id), *feats.at(nb), lo, hi, o.guided_max_epipolar_px, o.guided_ratio);
    const auto& im1 = rec->images.at(id);
    const auto& im2 = rec->images.at(nb);
    const auto& cam1 = rec->cameras.at(im1.camera_id);
    const auto& cam2 = rec->cameras.at(im2.camera_id);
    for (const auto& m : matches) {
      if (im1.point3d_ids[m.idx1] != core::kNoPoint3D || im2.point3d_ids[m.idx2] != core::kNoPoint3D) continue;
      const std::vector<core::Pose> poses = {im1.pose, im2.pose};
      const std::vector<Eigen::Vector2d> xs = {cam1.Unproject(im1.points2d[m.idx1]).head<2>(),
                                               cam2.Unproject(im2.points2d[m.idx2]).head<2>()};
      Eigen::Vector3d X;
      if (!geometry::TriangulateDLT(poses, xs, &X)) continue;
      geometry::RefinePoint(poses, xs, &X);
      if (geometry::TriangulationAngle(im1.pose.Centre(), im2.pose.Centre(), X) < o.tri_min_angle_deg * kDeg) continue;
      if (ReprojectionError(*rec, im1, im1.points2d[m.idx1], X) > o.tri_max_error_px ||
          ReprojectionError(*rec, im2, im2.points2d[m.idx2], X) > o.tri_max_error_px)
        continue;
      core::Point3D p;
      p.id = (*next_pid)++;
      p.xyz = X;
      const auto& colors = feats.at(id)->colors;
      if (colors.size() > m.idx1) p.rgb = colors[m.idx1];
      p.track = {{id, m.idx1}, {nb, m.idx2}};
      rec->images.at(id).point3d_ids[m.idx1] = static_cast<int64_t>(p.id);
      rec->images.at(nb).point3d_ids[m.idx2] = static_cast<int64_t>(p.id);
      rec->points[p.id] = std::move(p);
      ++added;
    }
  }
  return added;
}

// The whole model adjusted with the intrinsics held (the mapper has calibrated them on the larger part of the
// survey), observations above the bound dropped; a new image left with too few observations is taken out again,
// and points left with a one-image track are deleted.
void AdjustAfterRelocalisation(core::Reconstruction* rec, const std::vector<uint32_t>& added,
                               const RelocaliseOptions& o, RelocaliseStats* stats) {
  BundleAdjustmentConfig config;
  for (const auto& [cid, cam] : rec->cameras) config.constant_cameras.insert(cid);
  BundleAdjustmentOptions ba;
  ba.max_iterations = o.ba_max_iterations;
  ba.refine_focal = ba.refine_k1 = ba.refine_k2 = false;
  BundleAdjust(rec, config, ba);
  FilterObservations(rec, o.filter_max_error_px);
  UpdatePointErrors(rec);
  for (uint32_t id : added) {
    const auto& ids = rec->images.at(id).point3d_ids;
    const int obs =
        static_cast<int>(std::count_if(ids.begin(), ids.end(), [](int64_t p) { return p != core::kNoPoint3D; }));
    if (obs >= o.pose.min_inliers / 2) continue;
    for (int64_t pid : ids)
      if (pid != core::kNoPoint3D) RemoveObservation(rec, static_cast<uint64_t>(pid), id);
    rec->images.erase(id);
    stats->registered.erase(std::find(stats->registered.begin(), stats->registered.end(), id));
    stats->still_failed[id] = "relocalised, but its observations did not survive the adjustment";
    spdlog::warn("relocalise: image {} dropped again after the adjustment ({} observations left)", id, obs);
  }
  std::vector<uint64_t> short_tracks;
  for (const auto& [pid, p] : rec->points)
    if (p.track.size() < 2) short_tracks.push_back(pid);
  for (uint64_t pid : short_tracks) DeletePoint(rec, pid);
}

}  // namespace

RelocaliseStats RelocaliseImages(core::Reconstruction* rec, const std::vector<RelocaliseCandidate>& candidates,
                                 const std::map<uint32_t, const features::FeatureSet*>& feats,
                                 const std::map<uint32_t, core::Camera>& cameras, const RelocaliseOptions& o) {
  o.Check();
  const auto start = std::chrono::steady_clock::now();
  RelocaliseStats stats;
  CheckRelocaliseInputs(*rec, candidates, feats, cameras);
  std::vector<RelocaliseCandidate> pending;
  for (const auto& c : candidates)
    if (!rec->images.count(c.image_id)) pending.push_back(c);
  if (pending.empty() || rec->points.empty()) return stats;
  uint64_t next_pid = rec->points.empty() ? 1 : rec->points.rbegin()->first + 1;
  auto camera_of = [&](const RelocaliseCandidate& c) -> const core::Camera& {
    return rec->cameras.count(c.camera_id) ? rec->cameras.at(c.camera_id) : cameras.at(c.camera_id);
  };

  for (int round = 0; round < o.max_rounds && !pending.empty(); ++round) {
    stats.rounds = round + 1;
    RelocalisePointBank bank;
    BuildPointBank(*rec, feats, &bank.descriptors, &bank.point_ids);
    if (bank.descriptors.rows() < o.pose.min_inliers) break;
    features::ImageDescriptors bank_desc(bank.descriptors, 0);
    // Poses of every pending image against the current model (parallel; the model is read only).
    std::vector<RelocaliseAttempt> attempts(pending.size());
    tbb::parallel_for(size_t{0}, pending.size(), [&](size_t k) {
      const auto& c = pending[k];
      attempts[k] = AttemptRelocalisation(*rec, c, *feats.at(c.image_id), bank, bank_desc, camera_of(c), o);
    });
    // Add the successful ones (in candidate order: deterministic).
    std::vector<uint32_t> added;
    std::vector<RelocaliseCandidate> still;
    for (size_t k = 0; k < pending.size(); ++k) {
      const auto& c = pending[k];
      const RelocaliseAttempt& at = attempts[k];
      if (!at.pose.success) {
        stats.still_failed[c.image_id] = at.why;
        still.push_back(c);
        continue;
      }
      stats.observations_added += AddRelocalisedImage(rec, c, *feats.at(c.image_id), at, camera_of(c), o);
      stats.still_failed.erase(c.image_id);
      stats.registered.push_back(c.image_id);
      added.push_back(c.image_id);
      spdlog::info("relocalise: {} registered against the model ({} of {} 2D-3D matches inliers)", c.name,
                   at.pose.num_inliers, at.matches.size());
    }
    pending.swap(still);
    if (added.empty()) break;
    for (uint32_t id : added) stats.points_added += TriangulateWithNeighbours(rec, id, feats, o, &next_pid);
    AdjustAfterRelocalisation(rec, added, o, &stats);
  }
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace fmv3d::sfm
