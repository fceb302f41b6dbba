#include "fmv3d/sfm/incremental_mapper.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/absolute_pose.h"
#include "fmv3d/geometry/triangulation.h"
#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/correspondence_graph.h"
#include "fmv3d/sfm/focal_scan.h"

namespace fmv3d::sfm {

void MapperOptions::Check() const {
  if (init_min_inliers < 8) throw Error("mapper: init_min_inliers must be ≥ 8");
  if (!(init_min_tri_angle_deg > 0)) throw Error("mapper: init_min_tri_angle_deg must be > 0");
  if (!(abs_pose_max_error_px > 0)) throw Error("mapper: abs_pose_max_error_px must be > 0");
  if (abs_pose_min_inliers < 4) throw Error("mapper: abs_pose_min_inliers must be ≥ 4");
  if (!(tri_max_error_px > 0) || !(filter_max_error_px > 0)) throw Error("mapper: error thresholds must be > 0");
  if (tri_min_angle_deg < 0 || filter_min_angle_deg < 0) throw Error("mapper: angles must be ≥ 0");
  if (local_ba_num_images < 1) throw Error("mapper: local_ba_num_images must be ≥ 1");
  if (local_ba_max_iterations < 1 || global_ba_max_iterations < 1 || final_ba_max_iterations < 1)
    throw Error("mapper: BA iteration limits must be ≥ 1");
  if (!(final_ba_function_tolerance > 0)) throw Error("mapper: final_ba_function_tolerance must be > 0");
  if (!(global_ba_growth_ratio > 1)) throw Error("mapper: global_ba_growth_ratio must be > 1");
  if (min_model_size < 2) throw Error("mapper: min_model_size must be ≥ 2");
  if (max_models < 1) throw Error("mapper: max_models must be ≥ 1");
  if (focal_scan_pairs < 1) throw Error("mapper: focal_scan_pairs must be ≥ 1");
  if (!(narrow_field_max_radius >= 0)) throw Error("mapper: narrow_field_max_radius must be ≥ 0");
}

namespace {

constexpr double kDeg = M_PI / 180.0;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

struct Timings {
  double init = 0, registration = 0, triangulation = 0, local_ba = 0, global_ba = 0, filtering = 0;
};

struct PairCandidate {
  const features::VerifiedPair* pair = nullptr;
  bool evaluated = false, valid = false;
  double h_ratio = 0;
  double median_angle_deg = 0;
  int num_good = 0;
  double focal_scale = 1;  // chosen multiple of the guessed focal (1 when the focal is known)
  core::Pose pose2;  // pose of image 2 with image 1 at the origin, unit baseline
};

class ModelBuilder {
 public:
  ModelBuilder(const MapperInput& input, const std::map<uint32_t, const MapperImage*>& images,
               const CorrespondenceGraph& graph, const MapperOptions& options, const std::set<uint32_t>& pool,
               Timings* timings)
      : input_(input), images_(images), graph_(graph), opt_(options), pool_(pool), t_(timings) {
    tri_min_angle_deg_ = opt_.tri_min_angle_deg;
    filter_min_angle_deg_ = opt_.filter_min_angle_deg;
  }

  bool Initialize();
  void Grow();
  core::Reconstruction& rec() { return rec_; }
  const std::map<uint32_t, std::string>& fail_reasons() const { return fail_reason_; }
  std::pair<uint32_t, uint32_t> init_pair() const { return {gauge1_, gauge2_}; }
  int num_global_ba() const { return num_global_ba_; }
  int num_relocalised() const { return num_relocalised_; }

 private:
  Eigen::Vector2d Normalized(const core::Camera& cam, const Eigen::Vector2d& uv) const {
    return cam.Unproject(uv).head<2>();
  }
  void EvaluatePair(PairCandidate* c) const;
  void ChooseFocal(const std::vector<PairCandidate>& cands);
  void TryFreeFocal();
  void DollyZoomFocalScan();
  bool TryInitialPair(const PairCandidate& c);
  void AddImage(uint32_t id, const core::Pose& pose);
  void AddObservation(uint64_t pid, uint32_t image_id, uint32_t kp);
  void DeletePoint(uint64_t pid);
  bool TriangulateObservations(const std::vector<core::TrackElement>& obs);
  void TriangulateKeypoint(uint32_t image_id, uint32_t kp);
  int CompletePoint(uint64_t pid);
  int MergePoint(uint64_t pid);
  bool PointHasImage(uint64_t pid, uint32_t image_id) const;
  int64_t PointOf(const core::TrackElement& el) const {
    auto it = rec_.images.find(el.image_id);
    return it == rec_.images.end() ? core::kNoPoint3D : it->second.point3d_ids[el.point2d_idx];
  }
  int TriangulateImage(uint32_t image_id);
  int Retriangulate();
  int FilterPoints(const std::set<uint64_t>* subset);
  int VisiblePoints(uint32_t image_id, double* score) const;
  bool TryRegister(uint32_t image_id);
  // 2D–3D correspondences of an image with the current model: keypoints, points, (keypoint, point id) pairs.
  void Correspondences2d3d(uint32_t image_id, std::vector<Eigen::Vector2d>* p2, std::vector<Eigen::Vector3d>* p3,
                           std::vector<std::pair<uint32_t, uint64_t>>* kps) const;
  int RelocaliseImages();
  void LocalBundleAdjust(uint32_t image_id);
  BundleAdjustmentSummary GlobalBundleAdjust(bool final_pass, bool principal_point = false);
  // After an image was registered: whether the model has grown enough for an intermediate global adjustment
  // (or the dolly-zoom scan, which ends with one, is about to run).
  bool GlobalBundleAdjustDue() const {
    const size_t n = rec_.images.size();
    if (focal_from_plateau_ && !dolly_done_ && static_cast<int>(n) >= opt_.focal_dolly_min_images) return true;
    if (static_cast<int>(n) < opt_.global_ba_every_image_below) return true;
    if (n < opt_.global_ba_growth_ratio * images_at_last_global_) return false;
    // Growth ends with a global adjustment anyway: when even the pool's remaining images cannot grow the model
    // by the ratio once more, that one comes sooner than the next intermediate one would, so this is skipped.
    const size_t remaining = pool_.size() - n;
    return remaining >= (opt_.global_ba_growth_ratio - 1) * n;
  }
  void TryPrincipalPoint();
  BundleAdjustmentOptions BaOptions() const;

  const MapperInput& input_;
  const std::map<uint32_t, const MapperImage*>& images_;
  const CorrespondenceGraph& graph_;
  uint64_t next_point_id_ = 1;
  double init_focal_scale_ = 1;
  // Focal held through growth: a trusted prior the user wants kept, or a telephoto scan's lower bound (then
  // tested once at the end, see TryFreeFocal). Narrow field: distortion is unobservable and stays fixed.
  bool focal_fixed_ = false, focal_from_plateau_ = false, narrow_field_ = false, dolly_done_ = false;
  // Angle thresholds of this model: the options', lowered for narrow-baseline (telephoto) models, see Initialize.
  double tri_min_angle_deg_ = 0, filter_min_angle_deg_ = 0;  // set in the constructor body
  const MapperOptions& opt_;
  std::set<uint32_t> pool_;
  int num_relocalised_ = 0;
  Timings* t_;
  core::Reconstruction rec_;
  uint32_t gauge1_ = 0, gauge2_ = 0;
  std::map<uint32_t, std::string> fail_reason_;
  std::map<uint32_t, int> trials_;
  std::map<uint32_t, int> visible_at_failure_;
  size_t images_at_last_global_ = 0;
  int num_global_ba_ = 0;
};

void ModelBuilder::ChooseFocal(const std::vector<PairCandidate>& cands) {
  if (cands.empty()) return;
  const uint32_t cid = images_.at(cands[0].pair->image_id1)->camera_id;
  const MapperCamera& mc = input_.cameras.at(cid);
  auto narrow = [&](double f) {
    // Radial distortion moves a point by ~k·r³: at r = half-diagonal / f < 0.1 it is far below the noise for any
    // plausible k, so refining k1/k2 there only lets them wander.
    return 0.5 * std::hypot(mc.camera.width, mc.camera.height) / f < opt_.narrow_field_max_radius;
  };
  if (mc.focal_known) {
    focal_fixed_ = opt_.fix_known_focal;
    narrow_field_ = narrow(mc.camera.f);
    return;
  }
  std::vector<FocalScanPair> pairs;
  for (size_t i = 0; i < cands.size() && static_cast<int>(pairs.size()) < opt_.focal_scan_pairs; ++i) {
    const auto& pr = *cands[i].pair;
    const MapperImage& im1 = *images_.at(pr.image_id1);
    const MapperImage& im2 = *images_.at(pr.image_id2);
    if (im1.camera_id != cid || im2.camera_id != cid) continue;
    FocalScanPair fp;
    for (const auto& m : pr.inliers) {
      fp.uv1.push_back(im1.keypoints[m.idx1]);
      fp.uv2.push_back(im2.keypoints[m.idx2]);
    }
    pairs.push_back(std::move(fp));
  }
  FocalScanOptions fo;
  fo.seed = opt_.seed;
  const FocalScanResult r = ScanFocal(mc.camera, pairs, fo);
  init_focal_scale_ = r.focal / mc.camera.f;
  focal_fixed_ = focal_from_plateau_ = r.plateau;
  narrow_field_ = narrow(r.focal);
  std::string curve;
  for (size_t i = 0; i < r.focals.size(); ++i) curve += fmt::format(" {:.0f}:{:.3f}", r.focals[i], r.scores[i]);
  spdlog::info("focal scan on {} pairs: {:.1f} px ({:.2f} x the guess){}{}", pairs.size(), r.focal,
               init_focal_scale_, r.plateau ? ", plateau: a lower bound, held until the final test" : "",
               narrow_field_ ? ", narrow field: distortion fixed" : "");
  spdlog::debug("focal scan (f: px²):{}", curve);
}

void ModelBuilder::EvaluatePair(PairCandidate* c) const {
  c->evaluated = true;
  const auto& pair = *c->pair;
  const MapperImage& im1 = *images_.at(pair.image_id1);
  const MapperImage& im2 = *images_.at(pair.image_id2);
  core::Camera cam1 = input_.cameras.at(im1.camera_id).camera;
  core::Camera cam2 = input_.cameras.at(im2.camera_id).camera;
  auto normalise = [&](std::vector<cv::Point2d>* p1, std::vector<cv::Point2d>* p2) {
    p1->clear();
    p2->clear();
    for (const auto& m : pair.inliers) {
      const Eigen::Vector2d a = Normalized(cam1, im1.keypoints[m.idx1]);
      const Eigen::Vector2d b = Normalized(cam2, im2.keypoints[m.idx2]);
      p1->emplace_back(a.x(), a.y());
      p2->emplace_back(b.x(), b.y());
    }
  };
  std::vector<cv::Point2d> p1, p2, u1, u2;
  for (const auto& m : pair.inliers) {
    u1.emplace_back(im1.keypoints[m.idx1].x(), im1.keypoints[m.idx1].y());
    u2.emplace_back(im2.keypoints[m.idx2].x(), im2.keypoints[m.idx2].y());
  }
  c->focal_scale = init_focal_scale_;
  cam1.f *= init_focal_scale_;
  cam2.f *= init_focal_scale_;
  normalise(&p1, &p2);
  if (p1.size() < 8) return;
  // Homography-dominated pairs (planar scene, pure rotation) give an unstable relative pose.
  if (pair.num_inliers_H > 0 && !pair.inliers.empty()) {
    c->h_ratio = static_cast<double>(pair.num_inliers_H) / pair.inliers.size();
  } else {
    cv::Mat hmask;
    const cv::Mat H = cv::findHomography(u1, u2, cv::RANSAC, 4.0, hmask, 2000, 0.999);
    c->h_ratio = H.empty() ? 0 : static_cast<double>(cv::countNonZero(hmask)) / p1.size();
  }
  const double f = 0.5 * (cam1.f + cam2.f);
  cv::Mat mask;
  cv::Mat E;
  try {
    E = cv::findEssentialMat(p1, p2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.9999,
                             opt_.tri_max_error_px / f, 5000, mask);
  } catch (const cv::Exception&) {
    return;
  }
  if (E.rows != 3 || E.cols != 3) return;  // several solutions stacked or none: degenerate
  cv::Mat R, t;
  const int n_front = cv::recoverPose(E, p1, p2, cv::Mat::eye(3, 3, CV_64F), R, t, mask);
  if (n_front < opt_.init_min_inliers / 2) return;
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  cv::cv2eigen(R, Re);
  cv::cv2eigen(t, te);
  c->pose2 = core::Pose(Eigen::Quaterniond(Re), te.normalized());
  const core::Pose pose1;
  std::vector<double> angles;
  for (size_t i = 0; i < p1.size(); ++i) {
    if (!mask.at<uint8_t>(static_cast<int>(i))) continue;
    const std::vector<core::Pose> poses = {pose1, c->pose2};
    const std::vector<Eigen::Vector2d> xs = {{p1[i].x, p1[i].y}, {p2[i].x, p2[i].y}};
    Eigen::Vector3d X;
    if (!geometry::TriangulateDLT(poses, xs, &X)) continue;
    if (!geometry::HasPositiveDepth(pose1, X) || !geometry::HasPositiveDepth(c->pose2, X)) continue;
    const double e1 = (cam1.Project(pose1.Transform(X)) - Eigen::Vector2d(u1[i].x, u1[i].y)).norm();
    const double e2 = (cam2.Project(c->pose2.Transform(X)) - Eigen::Vector2d(u2[i].x, u2[i].y)).norm();
    if (e1 > opt_.tri_max_error_px || e2 > opt_.tri_max_error_px) continue;
    angles.push_back(geometry::TriangulationAngle(pose1.Centre(), c->pose2.Centre(), X) / kDeg);
  }
  if (angles.size() < 8) return;
  std::nth_element(angles.begin(), angles.begin() + angles.size() / 2, angles.end());
  c->median_angle_deg = angles[angles.size() / 2];
  c->num_good = static_cast<int>(angles.size());
  c->valid = true;
}

void ModelBuilder::AddImage(uint32_t id, const core::Pose& pose) {
  const MapperImage& mi = *images_.at(id);
  if (!rec_.cameras.count(mi.camera_id)) rec_.cameras[mi.camera_id] = input_.cameras.at(mi.camera_id).camera;
  core::Image im;
  im.id = id;
  im.camera_id = mi.camera_id;
  im.name = mi.name;
  im.pose = pose;
  im.points2d = mi.keypoints;
  im.point3d_ids.assign(mi.keypoints.size(), core::kNoPoint3D);
  rec_.images[id] = std::move(im);
}

void ModelBuilder::AddObservation(uint64_t pid, uint32_t image_id, uint32_t kp) {
  auto& im = rec_.images.at(image_id);
  if (im.point3d_ids[kp] != core::kNoPoint3D) return;
  im.point3d_ids[kp] = static_cast<int64_t>(pid);
  rec_.points.at(pid).track.push_back({image_id, kp});
}

void ModelBuilder::DeletePoint(uint64_t pid) {
  auto it = rec_.points.find(pid);
  if (it == rec_.points.end()) return;
  for (const auto& el : it->second.track) rec_.images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
  rec_.points.erase(it);
}

bool ModelBuilder::TryInitialPair(const PairCandidate& c) {
  rec_ = core::Reconstruction();
  const auto& pair = *c.pair;
  AddImage(pair.image_id1, core::Pose());
  AddImage(pair.image_id2, c.pose2);
  for (auto& [cid, cam] : rec_.cameras) cam.f *= c.focal_scale;
  gauge1_ = pair.image_id1;
  gauge2_ = pair.image_id2;
  int made = 0;
  for (const auto& m : pair.inliers) {
    if (rec_.images.at(pair.image_id1).point3d_ids[m.idx1] != core::kNoPoint3D ||
        rec_.images.at(pair.image_id2).point3d_ids[m.idx2] != core::kNoPoint3D)
      continue;
    made += TriangulateObservations({{pair.image_id1, m.idx1}, {pair.image_id2, m.idx2}}) ? 1 : 0;
  }
  if (made < opt_.init_min_inliers / 2) return false;
  BundleAdjustmentConfig cfg;
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  for (const auto& [cid, cam] : rec_.cameras) cfg.constant_cameras.insert(cid);
  BundleAdjust(&rec_, cfg, BaOptions());
  FilterPoints(nullptr);
  return static_cast<int>(rec_.points.size()) >= opt_.init_min_inliers / 2;
}

bool ModelBuilder::Initialize() {
  const auto start = Clock::now();
  std::vector<PairCandidate> cands;
  for (const auto& p : input_.pairs)
    if (pool_.count(p.image_id1) && pool_.count(p.image_id2) &&
        static_cast<int>(p.inliers.size()) >= opt_.init_min_inliers) {
      PairCandidate c;
      c.pair = &p;
      cands.push_back(c);
    }
  std::stable_sort(cands.begin(), cands.end(), [](const PairCandidate& a, const PairCandidate& b) {
    return a.pair->inliers.size() > b.pair->inliers.size();
  });
  if (static_cast<int>(cands.size()) > opt_.init_max_candidates) cands.resize(opt_.init_max_candidates);
  ChooseFocal(cands);
  for (auto& c : cands) EvaluatePair(&c);
  // Strict first (enough angle, not planar), then relax the angle and finally accept planar pairs.
  const std::vector<std::pair<double, bool>> passes = {
      {opt_.init_min_tri_angle_deg, false},       {opt_.init_min_tri_angle_deg / 2, false},
      {opt_.init_min_tri_angle_deg / 4, false},   {opt_.init_min_tri_angle_deg / 2, true},
      {opt_.init_min_tri_angle_deg / 8, true},    {opt_.init_min_tri_angle_deg / 32, true}};
  std::set<const features::VerifiedPair*> tried;
  for (const auto& [min_angle, allow_planar] : passes) {
    std::vector<const PairCandidate*> ok;
    for (const auto& c : cands)
      if (c.valid && c.median_angle_deg >= min_angle && (allow_planar || c.h_ratio <= opt_.init_max_h_ratio) &&
          c.num_good >= opt_.init_min_inliers / 2 && !tried.count(c.pair))
        ok.push_back(&c);
    std::stable_sort(ok.begin(), ok.end(),
                     [](const PairCandidate* a, const PairCandidate* b) { return a->num_good > b->num_good; });
    for (const PairCandidate* c : ok) {
      tried.insert(c->pair);
      // Telephoto video sees the scene through a narrow cone: no pair reaches the usual angles. The model then
      // works with thresholds scaled to the baseline it has (points still need a measurable parallax).
      tri_min_angle_deg_ = std::min(opt_.tri_min_angle_deg, std::max(0.05, c->median_angle_deg / 3));
      filter_min_angle_deg_ = std::min(opt_.filter_min_angle_deg, tri_min_angle_deg_);
      if (TryInitialPair(*c)) {
        spdlog::info("initial pair {} + {}: {} points, median angle {:.2f}°, H ratio {:.2f}, focal {:.1f}, "
                     "min angle {:.2f}°",
                     images_.at(c->pair->image_id1)->name, images_.at(c->pair->image_id2)->name,
                     rec_.points.size(), c->median_angle_deg, c->h_ratio, rec_.cameras.begin()->second.f,
                     tri_min_angle_deg_);
        t_->init += Seconds(start);
        images_at_last_global_ = 2;
        return true;
      }
    }
  }
  rec_ = core::Reconstruction();
  t_->init += Seconds(start);
  return false;
}

bool ModelBuilder::PointHasImage(uint64_t pid, uint32_t image_id) const {
  for (const auto& el : rec_.points.at(pid).track)
    if (el.image_id == image_id) return true;
  return false;
}

bool ModelBuilder::TriangulateObservations(const std::vector<core::TrackElement>& obs) {
  const size_t n = obs.size();
  if (n < 2) return false;
  std::vector<core::Pose> poses(n);
  std::vector<Eigen::Vector2d> xs(n), uvs(n);
  std::vector<Eigen::Vector3d> centres(n);
  std::vector<const core::Camera*> cams(n);
  for (size_t i = 0; i < n; ++i) {
    const auto& im = rec_.images.at(obs[i].image_id);
    cams[i] = &rec_.cameras.at(im.camera_id);
    poses[i] = im.pose;
    uvs[i] = im.points2d[obs[i].point2d_idx];
    xs[i] = Normalized(*cams[i], uvs[i]);
    centres[i] = im.pose.Centre();
  }
  auto inliers_of = [&](const Eigen::Vector3d& X, std::vector<size_t>* in) {
    in->clear();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d xc = poses[i].Transform(X);
      if (xc.z() <= 0) continue;
      if ((cams[i]->Project(xc) - uvs[i]).norm() <= opt_.tri_max_error_px) in->push_back(i);
    }
  };
  // Small RANSAC over observation pairs: the correspondences can contain a wrong match.
  std::vector<size_t> best_in;
  const size_t m = std::min<size_t>(n, 10);
  for (size_t i = 0; i < m && best_in.size() < n; ++i)
    for (size_t j = i + 1; j < m; ++j) {
      Eigen::Vector3d X;
      if (!geometry::TriangulateDLT({poses[i], poses[j]}, {xs[i], xs[j]}, &X)) continue;
      if (geometry::TriangulationAngle(centres[i], centres[j], X) < tri_min_angle_deg_ * kDeg) continue;
      std::vector<size_t> in;
      inliers_of(X, &in);
      if (in.size() > best_in.size()) best_in = in;
      if (best_in.size() == n) break;
    }
  if (best_in.size() < 2) return false;
  std::vector<core::Pose> ps;
  std::vector<Eigen::Vector2d> xx;
  for (size_t i : best_in) {
    ps.push_back(poses[i]);
    xx.push_back(xs[i]);
  }
  Eigen::Vector3d X;
  if (!geometry::TriangulateDLT(ps, xx, &X)) return false;
  geometry::RefinePoint(ps, xx, &X);
  std::vector<size_t> in;
  inliers_of(X, &in);
  if (in.size() < 2) return false;
  std::vector<Eigen::Vector3d> cs;
  for (size_t i : in) cs.push_back(centres[i]);
  if (geometry::MaxTriangulationAngle(cs, X) < tri_min_angle_deg_ * kDeg) return false;
  const uint64_t pid = next_point_id_++;
  core::Point3D p;
  p.id = pid;
  p.xyz = X;
  const MapperImage& first = *images_.at(obs[in[0]].image_id);
  if (first.colors.size() == first.keypoints.size()) p.rgb = first.colors[obs[in[0]].point2d_idx];
  rec_.points[pid] = p;
  for (size_t i : in) AddObservation(pid, obs[i].image_id, obs[i].point2d_idx);
  return true;
}

void ModelBuilder::TriangulateKeypoint(uint32_t image_id, uint32_t kp) {
  const auto& corrs = graph_.Correspondences(image_id, kp);
  if (corrs.empty()) return;
  auto& im = rec_.images.at(image_id);
  if (im.point3d_ids[kp] != core::kNoPoint3D) return;
  // Continuation: join the best-fitting existing point among the correspondences.
  int64_t best_pid = core::kNoPoint3D;
  double best_err = opt_.tri_max_error_px;
  for (const auto& c : corrs) {
    const int64_t pid = PointOf(c);
    if (pid == core::kNoPoint3D || pid == best_pid) continue;
    const double e = ObservationError(rec_, image_id, kp, rec_.points.at(static_cast<uint64_t>(pid)).xyz);
    if (e <= best_err && !PointHasImage(static_cast<uint64_t>(pid), image_id)) {
      best_err = e;
      best_pid = pid;
    }
  }
  if (best_pid != core::kNoPoint3D) {
    AddObservation(static_cast<uint64_t>(best_pid), image_id, kp);
    return;
  }
  // Creation: this keypoint and its registered, untriangulated correspondences (one per image).
  std::vector<core::TrackElement> obs = {{image_id, kp}};
  std::set<uint32_t> seen = {image_id};
  for (const auto& c : corrs)
    if (rec_.images.count(c.image_id) && PointOf(c) == core::kNoPoint3D && seen.insert(c.image_id).second)
      obs.push_back(c);
  if (obs.size() >= 2) TriangulateObservations(obs);
}

int ModelBuilder::CompletePoint(uint64_t pid) {
  int added = 0;
  // Breadth-first over the correspondence graph: an added observation can bring further ones.
  for (size_t k = 0; k < rec_.points.at(pid).track.size(); ++k) {
    const core::TrackElement el = rec_.points.at(pid).track[k];
    for (const auto& c : graph_.Correspondences(el.image_id, el.point2d_idx)) {
      if (!rec_.images.count(c.image_id) || PointOf(c) != core::kNoPoint3D || PointHasImage(pid, c.image_id))
        continue;
      if (ObservationError(rec_, c.image_id, c.point2d_idx, rec_.points.at(pid).xyz) <= opt_.tri_max_error_px) {
        AddObservation(pid, c.image_id, c.point2d_idx);
        ++added;
      }
    }
  }
  return added;
}

int ModelBuilder::MergePoint(uint64_t pid) {
  int merged = 0;
  for (size_t k = 0; rec_.points.count(pid) && k < rec_.points.at(pid).track.size(); ++k) {
    const core::TrackElement el = rec_.points.at(pid).track[k];
    for (const auto& c : graph_.Correspondences(el.image_id, el.point2d_idx)) {
      const int64_t other = PointOf(c);
      if (other == core::kNoPoint3D || static_cast<uint64_t>(other) == pid) continue;
      auto& P = rec_.points.at(pid);
      auto& Q = rec_.points.at(static_cast<uint64_t>(other));
      bool ok = true;
      for (const auto& q : Q.track) ok = ok && !PointHasImage(pid, q.image_id);
      if (!ok) continue;
      // Candidate position: the better-supported point's; every observation of both must agree with it.
      const Eigen::Vector3d X = P.track.size() >= Q.track.size() ? P.xyz : Q.xyz;
      for (const auto& o : P.track) ok = ok && ObservationError(rec_, o.image_id, o.point2d_idx, X) <= opt_.tri_max_error_px;
      for (const auto& o : Q.track) ok = ok && ObservationError(rec_, o.image_id, o.point2d_idx, X) <= opt_.tri_max_error_px;
      if (!ok) continue;
      const auto qtrack = Q.track;
      DeletePoint(static_cast<uint64_t>(other));
      rec_.points.at(pid).xyz = X;
      for (const auto& o : qtrack) AddObservation(pid, o.image_id, o.point2d_idx);
      ++merged;
    }
  }
  return merged;
}

int ModelBuilder::TriangulateImage(uint32_t image_id) {
  const auto start = Clock::now();
  const size_t before = rec_.points.size();
  const auto& im = rec_.images.at(image_id);
  for (uint32_t kp = 0; kp < im.points2d.size(); ++kp) TriangulateKeypoint(image_id, kp);
  std::set<uint64_t> pts;
  for (int64_t pid : rec_.images.at(image_id).point3d_ids)
    if (pid != core::kNoPoint3D) pts.insert(static_cast<uint64_t>(pid));
  for (uint64_t pid : pts) {
    if (!rec_.points.count(pid)) continue;
    CompletePoint(pid);
    MergePoint(pid);
  }
  t_->triangulation += Seconds(start);
  return static_cast<int>(rec_.points.size()) - static_cast<int>(before);
}

int ModelBuilder::Retriangulate() {
  const auto start = Clock::now();
  const size_t before = rec_.points.size();
  std::vector<uint32_t> ids;
  for (const auto& [id, im] : rec_.images) ids.push_back(id);
  for (uint32_t id : ids)
    for (uint32_t kp = 0; kp < rec_.images.at(id).points2d.size(); ++kp) TriangulateKeypoint(id, kp);
  std::vector<uint64_t> pids;
  for (const auto& [pid, p] : rec_.points) pids.push_back(pid);
  int changed = 0;
  for (uint64_t pid : pids) {
    if (!rec_.points.count(pid)) continue;
    changed += CompletePoint(pid);
    changed += MergePoint(pid);
  }
  t_->triangulation += Seconds(start);
  return changed + static_cast<int>(rec_.points.size()) - static_cast<int>(before);
}

int ModelBuilder::FilterPoints(const std::set<uint64_t>* subset) {
  const auto start = Clock::now();
  std::vector<uint64_t> ids;
  if (subset)
    ids.assign(subset->begin(), subset->end());
  else
    for (const auto& [pid, p] : rec_.points) ids.push_back(pid);
  int removed = 0;
  for (uint64_t pid : ids) {
    auto it = rec_.points.find(pid);
    if (it == rec_.points.end()) continue;
    auto& p = it->second;
    std::vector<core::TrackElement> keep;
    for (const auto& el : p.track) {
      if (ObservationError(rec_, el.image_id, el.point2d_idx, p.xyz) <= opt_.filter_max_error_px)
        keep.push_back(el);
      else
        rec_.images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
    }
    p.track = keep;
    bool drop = p.track.size() < 2;
    if (!drop) {
      std::vector<Eigen::Vector3d> cs;
      for (const auto& el : p.track) cs.push_back(rec_.images.at(el.image_id).pose.Centre());
      drop = geometry::MaxTriangulationAngle(cs, p.xyz) < filter_min_angle_deg_ * kDeg;
    }
    if (drop) {
      DeletePoint(pid);
      ++removed;
    }
  }
  t_->filtering += Seconds(start);
  return removed;
}

int ModelBuilder::VisiblePoints(uint32_t image_id, double* score) const {
  const MapperImage& mi = *images_.at(image_id);
  const core::Camera& cam = input_.cameras.at(mi.camera_id).camera;
  constexpr int kLevels = 3;
  std::set<int> cells[kLevels];
  int count = 0;
  for (uint32_t kp = 0; kp < mi.keypoints.size(); ++kp) {
    bool seen = false;
    for (const auto& c : graph_.Correspondences(image_id, kp))
      if (PointOf(c) != core::kNoPoint3D) {
        seen = true;
        break;
      }
    if (!seen) continue;
    ++count;
    for (int l = 0; l < kLevels; ++l) {
      const int g = 2 << l;  // 2, 4, 8 cells per side
      const int cx = std::clamp(static_cast<int>(mi.keypoints[kp].x() / std::max(1, cam.width) * g), 0, g - 1);
      const int cy = std::clamp(static_cast<int>(mi.keypoints[kp].y() / std::max(1, cam.height) * g), 0, g - 1);
      cells[l].insert(cy * g + cx);
    }
  }
  if (score) {
    *score = 0;
    for (int l = 0; l < kLevels; ++l) *score += static_cast<double>(cells[l].size()) * (2 << l);
  }
  return count;
}

BundleAdjustmentOptions ModelBuilder::BaOptions() const {
  BundleAdjustmentOptions o;
  o.loss_scale_px = opt_.ba_loss_scale_px;
  const int n = static_cast<int>(rec_.images.size());
  o.refine_focal = n >= opt_.refine_focal_min_images && !focal_fixed_;
  // While the focal is only a telephoto lower bound, distortion would absorb the wrong perspective: hold it.
  const bool hold_distortion = narrow_field_ || (focal_from_plateau_ && !dolly_done_);
  o.refine_k1 = n >= opt_.refine_focal_min_images && !hold_distortion;
  o.refine_k2 = n >= opt_.refine_k2_min_images && !hold_distortion;
  o.refine_principal_point = false;  // only the final model-selection test frees it
  o.refine_tangential = opt_.refine_tangential && n >= opt_.refine_principal_point_min_images;
  return o;
}

void ModelBuilder::Correspondences2d3d(uint32_t image_id, std::vector<Eigen::Vector2d>* p2,
                                       std::vector<Eigen::Vector3d>* p3,
                                       std::vector<std::pair<uint32_t, uint64_t>>* kps) const {
  const MapperImage& mi = *images_.at(image_id);
  for (uint32_t kp = 0; kp < mi.keypoints.size(); ++kp) {
    std::set<int64_t> pids;
    for (const auto& c : graph_.Correspondences(image_id, kp)) {
      const int64_t pid = PointOf(c);
      if (pid == core::kNoPoint3D || !pids.insert(pid).second) continue;
      p2->push_back(mi.keypoints[kp]);
      p3->push_back(rec_.points.at(static_cast<uint64_t>(pid)).xyz);
      kps->emplace_back(kp, static_cast<uint64_t>(pid));
    }
  }
}

bool ModelBuilder::TryRegister(uint32_t image_id) {
  const auto start = Clock::now();
  const MapperImage& mi = *images_.at(image_id);
  std::vector<Eigen::Vector2d> p2;
  std::vector<Eigen::Vector3d> p3;
  std::vector<std::pair<uint32_t, uint64_t>> kps;  // (keypoint, point) per correspondence
  Correspondences2d3d(image_id, &p2, &p3, &kps);
  core::Camera cam = rec_.cameras.count(mi.camera_id) ? rec_.cameras.at(mi.camera_id)
                                                       : input_.cameras.at(mi.camera_id).camera;
  geometry::AbsolutePoseOptions po;
  po.max_error_px = opt_.abs_pose_max_error_px;
  po.min_inliers = opt_.abs_pose_min_inliers;
  po.min_inlier_ratio = opt_.abs_pose_min_inlier_ratio;
  const auto r = geometry::EstimateAbsolutePose(p2, p3, cam, po);
  t_->registration += Seconds(start);
  if (!r.success) {
    fail_reason_[image_id] = "absolute pose failed: " + std::to_string(r.num_inliers) + " inliers of " +
                             std::to_string(p2.size()) + " 2D-3D correspondences";
    return false;
  }
  AddImage(image_id, r.pose);
  for (size_t i = 0; i < kps.size(); ++i)
    if (r.inlier_mask[i] && rec_.images.at(image_id).point3d_ids[kps[i].first] == core::kNoPoint3D &&
        !PointHasImage(kps[i].second, image_id))
      AddObservation(kps[i].second, image_id, kps[i].first);
  fail_reason_.erase(image_id);
  return true;
}

// An image registered early, while its true neighbours were not yet in the model, can sit at a wrong pose that
// wrong correspondences support: a symmetric building seen from the opposite side of an orbit, repeated
// texture. Its true neighbours, registered later, offer 2D–3D correspondences that the wrong pose cannot use.
// A fresh absolute pose over all its correspondences finds them: when it is a different pose and explains
// clearly more correspondences than the current one (same pixel threshold for both: 1.5x + 20), the image is
// re-registered there (its observations dropped, the new inliers added, then triangulated).
int ModelBuilder::RelocaliseImages() {
  const auto start = Clock::now();
  Eigen::AlignedBox3d box;
  for (const auto& [id, im] : rec_.images) box.extend(im.pose.Centre());
  const double extent = box.diagonal().norm();
  int moved = 0;
  std::vector<uint32_t> ids;
  for (const auto& [id, im] : rec_.images)
    if (id != gauge1_ && id != gauge2_) ids.push_back(id);
  for (uint32_t id : ids) {
    auto& im = rec_.images.at(id);
    std::vector<Eigen::Vector2d> p2;
    std::vector<Eigen::Vector3d> p3;
    std::vector<std::pair<uint32_t, uint64_t>> kps;
    Correspondences2d3d(id, &p2, &p3, &kps);
    const core::Camera& cam = rec_.cameras.at(im.camera_id);
    int support = 0;  // correspondences the current pose explains
    for (size_t i = 0; i < p2.size(); ++i) {
      const Eigen::Vector3d xc = im.pose.Transform(p3[i]);
      support += xc.z() > 0 && (cam.Project(xc) - p2[i]).norm() <= opt_.abs_pose_max_error_px;
    }
    const int wanted = support + support / 2 + 20;
    if (static_cast<int>(p2.size()) < wanted) continue;
    geometry::AbsolutePoseOptions po;
    po.max_error_px = opt_.abs_pose_max_error_px;
    po.min_inliers = std::max(opt_.abs_pose_min_inliers, wanted);
    po.min_inlier_ratio = opt_.abs_pose_min_inlier_ratio;
    const auto r = geometry::EstimateAbsolutePose(p2, p3, cam, po);
    if (!r.success || r.num_inliers < wanted) continue;
    const double dc = (r.pose.Centre() - im.pose.Centre()).norm();
    const double da = core::RotationAngle(r.pose.q, im.pose.q);
    if (dc < 0.01 * extent && da < 1.0 * kDeg) continue;  // the same pose, better supported: nothing wrong
    int obs = 0;
    for (int64_t pid : im.point3d_ids) obs += pid != core::kNoPoint3D;
    spdlog::info("sparse: {} re-registered: its pose explained {} of {} 2D-3D correspondences ({} observations), "
                 "one {:.3g} away ({:.2f}°) explains {}",
                 im.name, support, p2.size(), obs, dc, da / kDeg, r.num_inliers);
    for (uint32_t kp = 0; kp < im.point3d_ids.size(); ++kp) {
      const int64_t pid = im.point3d_ids[kp];
      if (pid == core::kNoPoint3D) continue;
      auto& track = rec_.points.at(static_cast<uint64_t>(pid)).track;
      track.erase(std::remove_if(track.begin(), track.end(),
                                 [&](const core::TrackElement& el) { return el.image_id == id; }),
                  track.end());
      im.point3d_ids[kp] = core::kNoPoint3D;
      if (track.size() < 2) DeletePoint(static_cast<uint64_t>(pid));
    }
    im.pose = r.pose;
    for (size_t i = 0; i < kps.size(); ++i)
      if (r.inlier_mask[i] && rec_.points.count(kps[i].second) && im.point3d_ids[kps[i].first] == core::kNoPoint3D &&
          !PointHasImage(kps[i].second, id))
        AddObservation(kps[i].second, id, kps[i].first);
    TriangulateImage(id);
    ++moved;
  }
  t_->registration += Seconds(start);
  return moved;
}

void ModelBuilder::LocalBundleAdjust(uint32_t image_id) {
  const auto start = Clock::now();
  // Neighbours: the registered images sharing most points with the new one.
  std::map<uint32_t, int> shared;
  for (int64_t pid : rec_.images.at(image_id).point3d_ids) {
    if (pid == core::kNoPoint3D) continue;
    for (const auto& el : rec_.points.at(static_cast<uint64_t>(pid)).track)
      if (el.image_id != image_id) ++shared[el.image_id];
  }
  std::vector<std::pair<int, uint32_t>> order;
  for (const auto& [id, n] : shared) order.emplace_back(-n, id);
  std::sort(order.begin(), order.end());
  BundleAdjustmentConfig cfg;
  cfg.variable_images.insert(image_id);
  for (size_t i = 0; i < order.size() && static_cast<int>(i) < opt_.local_ba_num_images - 1; ++i)
    cfg.variable_images.insert(order[i].second);
  cfg.constant_images.insert(gauge1_);  // the gauge image never moves, so the frame stays put
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  for (const auto& [cid, cam] : rec_.cameras) cfg.constant_cameras.insert(cid);
  BundleAdjustmentOptions o = BaOptions();
  o.max_iterations = opt_.local_ba_max_iterations;
  // The new image starts at its PnP pose, its neighbours near their optimum: a relative cost decrease below
  // 1e-3 is close enough for the next registration (61-keyframe clip: 45% fewer local BA residual evaluations
  // than at 1e-4, the same final accuracy; the global BAs absorb the rest at ~18% more work of their own).
  o.function_tolerance = 1e-3;
  const auto s = BundleAdjust(&rec_, cfg, o);
  t_->local_ba += Seconds(start);
  spdlog::debug("local BA: {} residuals, {} iterations, {:.2f} s", s.num_residuals, s.num_iterations, s.seconds);
  std::set<uint64_t> pts;
  for (uint32_t id : cfg.variable_images)
    for (int64_t pid : rec_.images.at(id).point3d_ids)
      if (pid != core::kNoPoint3D) pts.insert(static_cast<uint64_t>(pid));
  FilterPoints(&pts);
}

BundleAdjustmentSummary ModelBuilder::GlobalBundleAdjust(bool final_pass, bool principal_point) {
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg;
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  BundleAdjustmentOptions o = BaOptions();
  o.refine_principal_point = principal_point;
  // Intermediate adjustments only need to be near the optimum (the next image and the final pass refine further).
  o.max_iterations = opt_.global_ba_max_iterations;
  o.function_tolerance = 1e-5;
  if (final_pass) {
    o.function_tolerance = opt_.final_ba_function_tolerance;
    o.max_iterations = opt_.final_ba_max_iterations;
  }
  const auto s = BundleAdjust(&rec_, cfg, o);
  ++num_global_ba_;
  t_->global_ba += Seconds(start);
  spdlog::debug("global BA ({} images, {} points): rms {:.3f} → {:.3f} px in {} iterations, {:.2f} s",
                rec_.images.size(), rec_.points.size(), s.initial_rms_px, s.final_rms_px, s.num_iterations,
                s.seconds);
  FilterPoints(nullptr);
  images_at_last_global_ = rec_.images.size();
  return s;
}

// The principal point is weakly constrained in many configurations (an orbit of cameras all looking at one
// centre: a shift trades against a common tilt), and freeing it there only adds noise to every rotation.
// Model selection: free it, and keep the result only when the squared error drops by far more than the two
// extra parameters explain for pure noise (Δχ² with σ² estimated from the fixed-point fit).
void ModelBuilder::TryPrincipalPoint() {
  BundleAdjustmentOptions o = BaOptions();
  o.loss = BundleAdjustmentOptions::Loss::kTrivial;  // χ² needs plain squared errors (outliers are filtered)
  // Δχ² = dof · (ss0 − ss1) / ss0: a relative cost tolerance of 1e-6 moves it by about dof · 1e-6 (≈ 1 for a
  // large model), far below the threshold, so the test needs no tighter convergence than that.
  o.function_tolerance = std::max(opt_.final_ba_function_tolerance, 1e-6);
  o.max_iterations = opt_.final_ba_max_iterations;
  BundleAdjustmentConfig cfg;
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  core::Reconstruction fixed = rec_;
  o.refine_principal_point = false;
  const auto s0 = BundleAdjust(&fixed, cfg, o);
  core::Reconstruction freed = fixed;  // starts at the fixed optimum: a few steps only
  o.refine_principal_point = true;
  const auto s1 = BundleAdjust(&freed, cfg, o);
  if (!s0.success || !s1.success) return;
  const double n = s0.num_residuals;
  const double ss0 = s0.final_rms_px * s0.final_rms_px * n, ss1 = s1.final_rms_px * s1.final_rms_px * n;
  const double dof = std::max(1.0, 2 * n - 6.0 * rec_.images.size() - 3.0 * rec_.points.size());
  const double chi2 = (ss0 - ss1) / std::max(ss0 / dof, 1e-12);
  const auto& cam = freed.cameras.begin()->second;
  const bool keep = chi2 > opt_.principal_point_min_chi2;
  spdlog::info("principal point test: Δχ² = {:.1f} → {} (free fit: {:.2f}, {:.2f})", chi2,
               keep ? "refined" : "kept fixed", cam.u0, cam.v0);
  if (keep) {
    rec_ = std::move(freed);
    GlobalBundleAdjust(true, true);
  }
}

// A telephoto scan's focal is the knee of a plateau: longer focals explain the two-view matches as well. With
// the whole model the perspective effects add up, so free the focal once and keep the result only when the
// squared error drops by far more than one extra parameter explains for pure noise (Δχ², as for the
// principal point); otherwise the scan's value stays.
void ModelBuilder::TryFreeFocal() {
  BundleAdjustmentOptions o = BaOptions();
  o.loss = BundleAdjustmentOptions::Loss::kTrivial;
  o.function_tolerance = std::max(opt_.final_ba_function_tolerance, 1e-6);
  o.max_iterations = opt_.final_ba_max_iterations;
  BundleAdjustmentConfig cfg;
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  core::Reconstruction fixed = rec_;
  o.refine_focal = false;
  const auto s0 = BundleAdjust(&fixed, cfg, o);
  core::Reconstruction freed = fixed;
  o.refine_focal = true;
  const auto s1 = BundleAdjust(&freed, cfg, o);
  if (!s0.success || !s1.success) return;
  const double n = s0.num_residuals;
  const double ss0 = s0.final_rms_px * s0.final_rms_px * n, ss1 = s1.final_rms_px * s1.final_rms_px * n;
  const double dof = std::max(1.0, 2 * n - 6.0 * rec_.images.size() - 3.0 * rec_.points.size());
  const double chi2 = (ss0 - ss1) / std::max(ss0 / dof, 1e-12);
  const double f0 = fixed.cameras.begin()->second.f, f1 = freed.cameras.begin()->second.f;
  const bool keep = chi2 > opt_.focal_min_chi2 && f1 > 0;
  spdlog::info("focal test: Δχ² = {:.1f} → {} (free fit: {:.1f} px, held: {:.1f} px)", chi2,
               keep ? "refined" : "kept at the scan's value", f1, f0);
  if (keep) {
    focal_fixed_ = false;
    rec_ = std::move(freed);
    GlobalBundleAdjust(true);
  }
}

// Multi-view focal scan for a telephoto model whose two-view scan only gave a lower bound. Lengthening the
// focal by k while moving every camera back along its axis by (k − 1) times its median depth keeps the
// projections almost unchanged (a dolly zoom), so each candidate starts near its own optimum and a short BA
// with the focal held at the candidate measures how well that focal explains all views together — the
// perspective effects too small to see in one pair add up over the model.
void ModelBuilder::DollyZoomFocalScan() {
  dolly_done_ = true;
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg;
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  BundleAdjustmentOptions o = BaOptions();
  o.refine_focal = false;
  o.refine_k1 = o.refine_k2 = false;  // distortion would absorb the perspective the scan measures
  // Each candidate's rms is compared with the others': the budget the scan was tuned with (2x the former
  // intermediate global BA limit of 10), independent of the intermediate BAs' own.
  o.max_iterations = 20;
  o.function_tolerance = 1e-6;
  double best_rms = std::numeric_limits<double>::infinity(), best_k = 1, rms_at_lower_bound = 0, rms_next = 0;
  core::Reconstruction best_rec;
  std::string curve;
  // Continuation: each candidate starts from the previous one's optimum (a step of √2), so the BA follows the
  // valley even when the first model (built at the lower bound) is far from affine.
  core::Reconstruction m = rec_;
  const double step = std::sqrt(2.0);
  for (double k = 1; k <= opt_.focal_dolly_max_factor * 1.0001; k *= step) {
    const double dk = k == 1 ? 1 : step;
    for (auto& [cid, cam] : m.cameras) cam.f *= dk;
    for (auto& [iid, im] : m.images) {
      std::vector<double> depths;
      for (int64_t pid : im.point3d_ids)
        if (pid != core::kNoPoint3D) depths.push_back(im.pose.Transform(m.points.at(static_cast<uint64_t>(pid)).xyz).z());
      if (depths.empty()) continue;
      std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
      im.pose.t.z() += (dk - 1) * depths[depths.size() / 2];
    }
    const auto sm = BundleAdjust(&m, cfg, o);
    if (!sm.success) continue;
    curve += fmt::format(" {:.0f}:{:.4f}", m.cameras.begin()->second.f, sm.final_rms_px);
    if (k == 1) rms_at_lower_bound = sm.final_rms_px;
    else if (rms_next == 0) rms_next = sm.final_rms_px;
    if (sm.final_rms_px < best_rms) {
      best_rms = sm.final_rms_px;
      best_k = k;
      best_rec = m;
    }
  }
  t_->global_ba += Seconds(start);
  spdlog::info("focal dolly-zoom scan on {} images: x{:.2f} → {:.1f} px ({:.1f} s); rms px by focal:{}",
               rec_.images.size(), best_k, best_rec.cameras.empty() ? 0.0 : best_rec.cameras.begin()->second.f,
               Seconds(start), curve);
  // The two-view scan's "lower bound" can be wrong for an ordinary lens (a 40-frame 960x540 orbit: bound 1452 px,
  // true 831). Then the error rises steeply from the bound on — no plateau — and holding the focal there builds
  // the whole model on it (0.08% centre error, distortion absorbing the rest). The data do determine the focal:
  // release it to bundle adjustment from here, as for any guess.
  if (best_k == 1 && rms_at_lower_bound > 0 && rms_next > 1.2 * rms_at_lower_bound) {
    focal_fixed_ = focal_from_plateau_ = false;
    spdlog::info("focal: the error rises from the scan's lower bound on ({:.3f} → {:.3f} px): no plateau, the focal "
                 "is refined from here", rms_at_lower_bound, rms_next);
  }
  if (best_k != 1 && !best_rec.images.empty()) {
    rec_ = std::move(best_rec);
    narrow_field_ = narrow_field_ || 0.5 * std::hypot(rec_.cameras.begin()->second.width,
                                                      rec_.cameras.begin()->second.height) /
                                             rec_.cameras.begin()->second.f < opt_.narrow_field_max_radius;
    FilterPoints(nullptr);
  }
}

void ModelBuilder::Grow() {
  GlobalBundleAdjust(false);
  for (;;) {
    std::vector<std::pair<double, uint32_t>> cands;
    for (uint32_t id : pool_) {
      if (rec_.images.count(id)) continue;
      double score = 0;
      const int vis = VisiblePoints(id, &score);
      if (vis < opt_.min_visible_points) {
        if (!fail_reason_.count(id) || fail_reason_[id].rfind("too few", 0) == 0)
          fail_reason_[id] = "too few triangulated points visible (" + std::to_string(vis) + " < " +
                             std::to_string(opt_.min_visible_points) + ")";
        continue;
      }
      // A frame that failed is retried only after the model offers it clearly more points.
      auto f = visible_at_failure_.find(id);
      if (f != visible_at_failure_.end() &&
          (vis < 1.25 * f->second + 5 || trials_[id] >= opt_.max_registration_trials))
        continue;
      cands.emplace_back(-score, id);
    }
    if (cands.empty()) break;
    std::sort(cands.begin(), cands.end());
    bool registered = false;
    for (const auto& [neg, id] : cands) {
      if (TryRegister(id)) {
        const int made = TriangulateImage(id);
        // A global adjustment due now covers the new image and its neighbours too: the local one would only
        // be repeated by it (while the model is small, both used to run after every image).
        if (!GlobalBundleAdjustDue()) LocalBundleAdjust(id);
        spdlog::debug("registered {} ({} images, +{} points)", images_.at(id)->name, rec_.images.size(), made);
        registered = true;
        break;
      }
      ++trials_[id];
      visible_at_failure_[id] = VisiblePoints(id, nullptr);
    }
    if (!registered) break;
    if (focal_from_plateau_ && !dolly_done_ && static_cast<int>(rec_.images.size()) >= opt_.focal_dolly_min_images) {
      DollyZoomFocalScan();
      GlobalBundleAdjust(false);
      Retriangulate();
      continue;
    }
    if (GlobalBundleAdjustDue()) {
      GlobalBundleAdjust(false);
      Retriangulate();
    }
  }
  // Final polish: retriangulate with the refined cameras, then a tight global BA.
  GlobalBundleAdjust(false);
  if (opt_.relocalise && (num_relocalised_ = RelocaliseImages()) > 0) GlobalBundleAdjust(false);
  Retriangulate();
  GlobalBundleAdjust(true);
  if (focal_from_plateau_ && static_cast<int>(rec_.images.size()) >= opt_.refine_principal_point_min_images)
    TryFreeFocal();
  if (static_cast<int>(rec_.images.size()) >= opt_.refine_principal_point_min_images) TryPrincipalPoint();
  UpdatePointErrors(&rec_);
}

}  // namespace

MapperResult RunIncrementalMapper(const MapperInput& input, const MapperOptions& options) {
  options.Check();
  const auto start = Clock::now();
  MapperResult result;
  std::map<uint32_t, const MapperImage*> images;
  std::map<uint32_t, size_t> num_kp;
  for (const auto& im : input.images) {
    if (!input.cameras.count(im.camera_id))
      throw Error("mapper: image " + im.name + " refers to unknown camera " + std::to_string(im.camera_id));
    input.cameras.at(im.camera_id).camera.Validate();
    if (images.count(im.id)) throw Error("mapper: duplicate image id " + std::to_string(im.id));
    images[im.id] = &im;
    num_kp[im.id] = im.keypoints.size();
  }
  const CorrespondenceGraph graph(num_kp, input.pairs);
  std::map<uint32_t, int> pair_count;
  for (const auto& p : input.pairs)
    if (images.count(p.image_id1) && images.count(p.image_id2) && !p.inliers.empty()) {
      ++pair_count[p.image_id1];
      ++pair_count[p.image_id2];
    }
  std::set<uint32_t> pool;
  std::map<uint32_t, std::string> reasons;
  for (const auto& [id, im] : images) {
    if (pair_count[id] > 0)
      pool.insert(id);
    else
      reasons[id] = im->keypoints.empty() ? "no features (blank or textureless frame)"
                                          : "no verified matches with any other image";
  }
  spdlog::info("mapper: {} images, {} verified pairs, {} correspondences ({} invalid skipped)", images.size(),
               input.pairs.size(), graph.NumCorrespondences(), graph.NumSkipped());

  Timings timings;
  std::vector<std::map<uint32_t, std::string>> model_fail;
  int relocalised = 0;
  while (static_cast<int>(pool.size()) >= options.min_model_size &&
         static_cast<int>(result.models.size()) < options.max_models) {
    ModelBuilder builder(input, images, graph, options, pool, &timings);
    if (!builder.Initialize()) break;
    builder.Grow();
    relocalised += builder.num_relocalised();
    auto& rec = builder.rec();
    for (const auto& [id, im] : rec.images) pool.erase(id);
    for (const auto& [id, why] : builder.fail_reasons())
      if (!reasons.count(id)) reasons[id] = why;
    if (static_cast<int>(rec.images.size()) < options.min_model_size) continue;
    spdlog::info("model {}: {} images, {} points", result.models.size(), rec.images.size(), rec.points.size());
    result.models.push_back(std::move(rec));
  }
  std::stable_sort(result.models.begin(), result.models.end(),
                   [](const core::Reconstruction& a, const core::Reconstruction& b) {
                     return a.images.size() > b.images.size();
                   });
  for (size_t m = 0; m < result.models.size(); ++m)
    for (const auto& [id, im] : result.models[m].images) {
      if (m == 0)
        reasons.erase(id);
      else
        reasons[id] = "registered in disconnected model " + std::to_string(m) + " (" +
                      std::to_string(result.models[m].images.size()) + " images)";
    }
  for (uint32_t id : pool)
    if (!reasons.count(id)) reasons[id] = "no initial pair or connection to a model";
  for (const auto& [id, im] : images)
    if (!(result.models.size() && result.models[0].images.count(id)) && !reasons.count(id))
      reasons[id] = "not registered";
  result.left_out = reasons;
  result.stats = {{"correspondences", graph.NumCorrespondences()},
                  {"invalid_matches_skipped", graph.NumSkipped()},
                  {"models", result.models.size()},
                  {"relocalised_images", relocalised},
                  {"seconds", {{"initial_pair", timings.init},
                               {"absolute_pose", timings.registration},
                               {"triangulation", timings.triangulation},
                               {"local_ba", timings.local_ba},
                               {"global_ba", timings.global_ba},
                               {"filtering", timings.filtering},
                               {"total", Seconds(start)}}}};
  return result;
}

}  // namespace fmv3d::sfm
