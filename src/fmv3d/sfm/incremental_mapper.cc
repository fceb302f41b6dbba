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
#include "fmv3d/sfm/dolly_zoom_scan.h"
#include "fmv3d/sfm/focal_scan.h"
#include "fmv3d/sfm/mapper_primitives.h"
#include "fmv3d/sfm/self_calibration.h"
#include "fmv3d/sfm/track_builder.h"
#include "fmv3d/sfm/triangulator.h"

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
  if (!(self_calibration_min_delta_chi2 >= 0)) throw Error("mapper: self_calibration_min_delta_chi2 must be ≥ 0");
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
  core::Pose pose2;        // pose of image 2 with image 1 at the origin, unit baseline
};

// Why an image of the pool is not (yet) in the model; turned into a sentence only for MapperResult::left_out.
struct RegistrationFailure {
  enum class Kind { kTooFewVisiblePoints, kAbsolutePose };
  Kind kind = Kind::kTooFewVisiblePoints;
  int count = 0;  // visible points, or absolute-pose inliers
  int of = 0;     // the minimum needed, or the 2D–3D correspondences tried
  std::string Describe() const {
    if (kind == Kind::kTooFewVisiblePoints)
      return "too few triangulated points visible (" + std::to_string(count) + " < " + std::to_string(of) + ")";
    return "absolute pose failed: " + std::to_string(count) + " inliers of " + std::to_string(of) +
           " 2D-3D correspondences";
  }
};

// One step of the growth loop.
enum class GrowthStep {
  kRegistered,   // an image was registered (and triangulated, locally adjusted)
  kNoCandidate,  // no image left that sees enough of the model or deserves another trial
  kAllFailed,    // every candidate was tried and failed
};

class ModelBuilder {
 public:
  ModelBuilder(const MapperInput& input, const std::map<uint32_t, const MapperImage*>& images,
               const CorrespondenceGraph& graph, const MapperOptions& options, const std::set<uint32_t>& pool,
               Timings* timings)
      : input_(input),
        images_(images),
        graph_(graph),
        opt_(options),
        pool_(pool),
        t_(timings),
        triangulator_(graph, &rec_,
                      {options.tri_max_error_px, options.tri_min_angle_deg, options.tri_ignore_two_view_tracks},
                      [this](uint32_t image_id, uint32_t kp, Eigen::Matrix<uint8_t, 3, 1>* rgb) {
                        const MapperImage& mi = *images_.at(image_id);
                        if (mi.colors.size() != mi.keypoints.size()) return false;
                        *rgb = mi.colors[kp];
                        return true;
                      }) {
    filter_.max_error_px = opt_.filter_max_error_px;
    filter_.min_angle_deg = opt_.filter_min_angle_deg;
  }

  bool Initialize();
  void Grow();
  core::Reconstruction& rec() { return rec_; }
  std::map<uint32_t, std::string> fail_reasons() const {
    std::map<uint32_t, std::string> out;
    for (const auto& [id, f] : fail_reason_) out[id] = f.Describe();
    return out;
  }
  std::pair<uint32_t, uint32_t> init_pair() const { return {gauge1_, gauge2_}; }
  int num_global_ba() const { return num_global_ba_; }
  int num_relocalised() const { return num_relocalised_; }
  const std::vector<NestedModelTestResult>& self_calibration() const { return self_calibration_; }

 private:
  Eigen::Vector2d Normalized(const core::Camera& cam, const Eigen::Vector2d& uv) const {
    return cam.Unproject(uv).head<2>();
  }
  void EvaluatePair(PairCandidate* c) const;
  void ChooseFocal(const std::vector<PairCandidate>& cands);
  void DollyZoomFocalScan();
  bool TryInitialPair(const PairCandidate& c);
  void AddImage(uint32_t id, const core::Pose& pose);
  GrowthStep RegisterNextImage();
  // Timed wrappers of the primitives (mapper_primitives.h, triangulator.h) with this model's thresholds.
  int TriangulateImage(uint32_t image_id);
  int Retriangulate();
  int FilterPoints(const std::set<uint64_t>* subset);
  int VisiblePoints(uint32_t image_id, double* score) const;
  Correspondences2D3D Correspondences(uint32_t image_id) const {
    return FindCorrespondences2D3D(rec_, graph_, image_id, images_.at(image_id)->keypoints);
  }
  bool TryRegister(uint32_t image_id);
  // A configuration carrying the weights of the operator's tie points.
  BundleAdjustmentConfig NewBaConfig() const {
    BundleAdjustmentConfig cfg;
    cfg.weighted_from = input_.manual_from;
    cfg.observation_weight = input_.manual_weight;
    return cfg;
  }
  int RelocaliseImages();
  void LocalBundleAdjust(uint32_t image_id);
  BundleAdjustmentSummary GlobalBundleAdjust(bool final_pass);
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
  // The final nested-model test of one intrinsic group (self_calibration.h); true when it was freed.
  bool TrySelfCalibration(IntrinsicGroup group);
  // The final tests of the radial terms refined through growth, against the prior's values (k2, then k1 when k2
  // is not needed); true when the model changed.
  bool TryRadialSelfCalibration();
  // One radial term's test; *held is set when it goes back to the prior. True when the model changed.
  bool TestRadialTerm(IntrinsicGroup group, bool* held);
  // One nested-model test on *rec (rec_ or a copy), recorded in self_calibration_.
  bool RunSelfCalibrationTest(IntrinsicGroup group, core::Reconstruction* rec);
  BundleAdjustmentOptions BaOptions() const;

  const MapperInput& input_;
  const std::map<uint32_t, const MapperImage*>& images_;
  const CorrespondenceGraph& graph_;
  double init_focal_scale_ = 1;
  // Focal held through growth: a trusted prior the user wants kept, or a telephoto scan's lower bound (then
  // tested once at the end). Narrow field: distortion is unobservable and stays fixed.
  bool focal_fixed_ = false, focal_from_plateau_ = false, narrow_field_ = false, dolly_done_ = false;
  const MapperOptions& opt_;
  std::set<uint32_t> pool_;
  int num_relocalised_ = 0;
  Timings* t_;
  core::Reconstruction rec_;
  // Angle thresholds of this model: the options', lowered for narrow-baseline (telephoto) models, see Initialize.
  IncrementalTriangulator triangulator_;
  PointFilterOptions filter_;
  uint32_t gauge1_ = 0, gauge2_ = 0;
  std::map<uint32_t, RegistrationFailure> fail_reason_;
  std::map<uint32_t, int> trials_;
  std::map<uint32_t, int> visible_at_failure_;
  size_t images_at_last_global_ = 0;
  int num_global_ba_ = 0;
  std::set<IntrinsicGroup> freed_groups_;   // freed by the final self-calibration tests
  bool k1_held_ = false, k2_held_ = false;  // back at the prior's values by the final tests
  std::vector<NestedModelTestResult> self_calibration_;
};

int ModelBuilder::TriangulateImage(uint32_t image_id) {
  const auto start = Clock::now();
  const int made = triangulator_.TriangulateImage(image_id);
  t_->triangulation += Seconds(start);
  return made;
}

int ModelBuilder::Retriangulate() {
  const auto start = Clock::now();
  const int changed = triangulator_.Retriangulate();
  t_->triangulation += Seconds(start);
  return changed;
}

int ModelBuilder::FilterPoints(const std::set<uint64_t>* subset) {
  const auto start = Clock::now();
  const int removed = sfm::FilterPoints(&rec_, subset, filter_);
  t_->filtering += Seconds(start);
  return removed;
}

int ModelBuilder::VisiblePoints(uint32_t image_id, double* score) const {
  const MapperImage& mi = *images_.at(image_id);
  const core::Camera& cam = input_.cameras.at(mi.camera_id).camera;
  return CountVisiblePoints(rec_, graph_, image_id, mi.keypoints, cam.width, cam.height, score);
}

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
  spdlog::info("focal scan on {} pairs: {:.1f} px ({:.2f} x the guess){}{}", pairs.size(), r.focal, init_focal_scale_,
               r.plateau ? ", plateau: a lower bound, held until the final test" : "",
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
    E = cv::findEssentialMat(p1, p2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.9999, opt_.tri_max_error_px / f, 5000,
                             mask);
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

bool ModelBuilder::TryInitialPair(const PairCandidate& c) {
  rec_ = core::Reconstruction();
  const auto& pair = *c.pair;
  AddImage(pair.image_id1, core::Pose());
  AddImage(pair.image_id2, c.pose2);
  for (auto& [cid, cam] : rec_.cameras) cam.f *= c.focal_scale;
  gauge1_ = pair.image_id1;
  gauge2_ = pair.image_id2;
  // The pair keeps its two-view matches (the triangulator skips them later): dropping them here lengthens the
  // mean track (fountain-P11 4.52 → 4.64, Herz-Jesus-P8 3.77 → 4.02) but moved the weakly determined v0 of
  // synthetic orbits with an off-centre principal point within its σ, and their figures with it (24 frames, 15 m
  // altitude swing: rotation 0.063° → 0.221°, focal 0.066% → 0.23%).
  int made = 0;
  for (const auto& m : pair.inliers) {
    if (rec_.images.at(pair.image_id1).point3d_ids[m.idx1] != core::kNoPoint3D ||
        rec_.images.at(pair.image_id2).point3d_ids[m.idx2] != core::kNoPoint3D)
      continue;
    made += triangulator_.CreatePoint({{pair.image_id1, m.idx1}, {pair.image_id2, m.idx2}}) != core::kNoPoint3D;
  }
  if (made < opt_.init_min_inliers / 2) return false;
  BundleAdjustmentConfig cfg = NewBaConfig();
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
      {opt_.init_min_tri_angle_deg, false},     {opt_.init_min_tri_angle_deg / 2, false},
      {opt_.init_min_tri_angle_deg / 4, false}, {opt_.init_min_tri_angle_deg / 2, true},
      {opt_.init_min_tri_angle_deg / 8, true},  {opt_.init_min_tri_angle_deg / 32, true}};
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
      const double tri_min_angle_deg = std::min(opt_.tri_min_angle_deg, std::max(0.05, c->median_angle_deg / 3));
      triangulator_.set_min_angle_deg(tri_min_angle_deg);
      filter_.min_angle_deg = std::min(opt_.filter_min_angle_deg, tri_min_angle_deg);
      if (TryInitialPair(*c)) {
        spdlog::info(
            "initial pair {} + {}: {} points, median angle {:.2f}°, H ratio {:.2f}, focal {:.1f}, "
            "min angle {:.2f}°",
            images_.at(c->pair->image_id1)->name, images_.at(c->pair->image_id2)->name, rec_.points.size(),
            c->median_angle_deg, c->h_ratio, rec_.cameras.begin()->second.f, triangulator_.options().min_angle_deg);
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

BundleAdjustmentOptions ModelBuilder::BaOptions() const {
  BundleAdjustmentOptions o;
  o.loss_scale_px = opt_.ba_loss_scale_px;
  const int n = static_cast<int>(rec_.images.size());
  o.refine_focal = n >= opt_.refine_focal_min_images && !focal_fixed_;
  // While the focal is only a telephoto lower bound, distortion would absorb the wrong perspective: hold it.
  const bool hold_distortion = narrow_field_ || (focal_from_plateau_ && !dolly_done_);
  o.refine_k1 = n >= opt_.refine_focal_min_images && !hold_distortion && !k1_held_;
  o.refine_k2 = n >= opt_.refine_k2_min_images && !hold_distortion && !k2_held_;
  o.refine_principal_point = false;  // only the final model-selection tests free it (and aspect, tangential)
  o.refine_tangential = opt_.refine_tangential && n >= opt_.refine_principal_point_min_images;
  for (IntrinsicGroup g : freed_groups_) SetRefine(g, true, &o);
  return o;
}

bool ModelBuilder::TryRegister(uint32_t image_id) {
  const auto start = Clock::now();
  const MapperImage& mi = *images_.at(image_id);
  const Correspondences2D3D c = Correspondences(image_id);
  core::Camera cam =
      rec_.cameras.count(mi.camera_id) ? rec_.cameras.at(mi.camera_id) : input_.cameras.at(mi.camera_id).camera;
  geometry::AbsolutePoseOptions po;
  po.max_error_px = opt_.abs_pose_max_error_px;
  po.min_inliers = opt_.abs_pose_min_inliers;
  po.min_inlier_ratio = opt_.abs_pose_min_inlier_ratio;
  const auto r = geometry::EstimateAbsolutePose(c.points2d, c.points3d, cam, po);
  t_->registration += Seconds(start);
  if (!r.success) {
    fail_reason_[image_id] = {RegistrationFailure::Kind::kAbsolutePose, r.num_inliers,
                              static_cast<int>(c.points2d.size())};
    return false;
  }
  AddImage(image_id, r.pose);
  for (size_t i = 0; i < c.keypoint_point.size(); ++i) {
    const auto [kp, pid] = c.keypoint_point[i];
    if (r.inlier_mask[i] && rec_.images.at(image_id).point3d_ids[kp] == core::kNoPoint3D &&
        !PointHasImage(rec_, pid, image_id))
      AddObservation(&rec_, pid, image_id, kp);
  }
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
    const Correspondences2D3D c = Correspondences(id);
    const auto& p2 = c.points2d;
    const auto& p3 = c.points3d;
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
    spdlog::info(
        "sparse: {} re-registered: its pose explained {} of {} 2D-3D correspondences ({} observations), "
        "one {:.3g} away ({:.2f}°) explains {}",
        im.name, support, p2.size(), obs, dc, da / kDeg, r.num_inliers);
    DetachImage(&rec_, id);
    im.pose = r.pose;
    for (size_t i = 0; i < c.keypoint_point.size(); ++i) {
      const auto [kp, pid] = c.keypoint_point[i];
      if (r.inlier_mask[i] && rec_.points.count(pid) && im.point3d_ids[kp] == core::kNoPoint3D &&
          !PointHasImage(rec_, pid, id))
        AddObservation(&rec_, pid, id, kp);
    }
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
  BundleAdjustmentConfig cfg = NewBaConfig();
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

BundleAdjustmentSummary ModelBuilder::GlobalBundleAdjust(bool final_pass) {
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  BundleAdjustmentOptions o = BaOptions();
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
                rec_.images.size(), rec_.points.size(), s.initial_rms_px, s.final_rms_px, s.num_iterations, s.seconds);
  FilterPoints(nullptr);
  images_at_last_global_ = rec_.images.size();
  return s;
}

// Held through growth, freed at the end only when the data ask for it and determine it (self_calibration.h):
// a telephoto scan's focal is the knee of a plateau (longer focals explain the two-view matches as well); the
// principal point is weakly constrained in many configurations (an orbit of cameras all looking at one centre:
// a shift trades against a common tilt), and freeing it there only adds noise to every rotation; aspect and
// tangential distortion are small for most cameras. Each test starts from the previous one's result.
bool ModelBuilder::RunSelfCalibrationTest(IntrinsicGroup group, core::Reconstruction* rec) {
  BundleAdjustmentOptions o = BaOptions();
  // Δχ² = dof · (ss0 − ss1) / ss0: a relative cost tolerance of 1e-6 moves it by about dof · 1e-6 (≈ 1 for a
  // large model), far below the price of a parameter for such a model, so the test needs no tighter convergence.
  o.function_tolerance = std::max(opt_.final_ba_function_tolerance, 1e-6);
  o.max_iterations = opt_.final_ba_max_iterations;
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  NestedModelTestOptions to;
  // k1, k2 were free through growth: a fixed threshold would drop a real lens's distortion (1000 held the true
  // k1 = −0.08 of a 40-image synthetic orbit at Δχ² = 972), so their tests always use BIC's.
  const bool radial = group == IntrinsicGroup::kK1 || group == IntrinsicGroup::kK2;
  to.min_delta_chi2 = radial ? 0 : opt_.self_calibration_min_delta_chi2;
  const auto start = Clock::now();
  NestedModelTestResult r = TestNestedModel(rec, cfg, o, group, to);
  t_->global_ba += Seconds(start);
  std::string values;
  for (size_t i = 0; i < r.parameters.size(); ++i)
    values += fmt::format(" {:.6g}→{:.6g}{}", r.held_values[i], r.freed_values[i],
                          i < r.sigmas.size() ? fmt::format(" (σ {:.3g})", r.sigmas[i]) : std::string());
  spdlog::info("self-calibration, {}: Δχ² = {:.1f} vs {:.1f}, 1σ at the corner {:.3f} px vs rms {:.3f} px → {};{}",
               ToString(group), r.delta_chi2, r.threshold, r.max_sigma_px, r.rms_freed_px, ToString(r.decision),
               values);
  const bool freed = r.freed_decision();
  // k1, k2 were free already: their tests only decide whether they are held (k1_held_, k2_held_).
  if (freed && group != IntrinsicGroup::kK1 && group != IntrinsicGroup::kK2) freed_groups_.insert(group);
  self_calibration_.push_back(std::move(r));
  return freed;
}

bool ModelBuilder::TrySelfCalibration(IntrinsicGroup group) { return RunSelfCalibrationTest(group, &rec_); }

// k1 and k2 follow the data through growth (a guessed prior says nothing about the lens). On photos that were
// undistorted (or a lens without measurable distortion) they only trade against the focal and the principal
// point. Nested models: k2 is tested first (null: k2 at the prior, k1 free), then, when k2 is not needed, k1
// (null: both at the prior); a term stays free only when both questions of self_calibration.h say so. Held, the
// final adjustment re-fits the model with it at the prior.
bool ModelBuilder::TestRadialTerm(IntrinsicGroup group, bool* held) {
  core::Reconstruction start = rec_;
  for (auto& [cid, cam] : start.cameras) {
    const core::Camera& prior = input_.cameras.at(cid).camera;
    (group == IntrinsicGroup::kK1 ? cam.k1 : cam.k2) = group == IntrinsicGroup::kK1 ? prior.k1 : prior.k2;
  }
  const bool freed = RunSelfCalibrationTest(group, &start);
  if (self_calibration_.back().decision == NestedModelDecision::kFailed) return false;  // keep the model as it was
  rec_ = std::move(start);
  *held = !freed;
  return true;
}

bool ModelBuilder::TryRadialSelfCalibration() {
  // One camera: the test prices each term as one parameter.
  if (rec_.cameras.size() != 1) return false;
  bool changed = false;
  if (BaOptions().refine_k2) changed = TestRadialTerm(IntrinsicGroup::kK2, &k2_held_);
  if (BaOptions().refine_k1 && !BaOptions().refine_k2)
    changed = TestRadialTerm(IntrinsicGroup::kK1, &k1_held_) || changed;
  return changed;
}

void ModelBuilder::DollyZoomFocalScan() {
  dolly_done_ = true;
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  DollyZoomScanOptions so;
  so.max_factor = opt_.focal_dolly_max_factor;
  DollyZoomScanResult r = ScanFocalDollyZoom(rec_, cfg, BaOptions(), so);
  t_->global_ba += Seconds(start);
  spdlog::info("focal dolly-zoom scan on {} images: x{:.2f} → {:.1f} px ({:.1f} s); rms px by focal:{}",
               rec_.images.size(), r.best_factor, r.best.cameras.empty() ? 0.0 : r.best.cameras.begin()->second.f,
               Seconds(start), r.curve);
  // The two-view scan's "lower bound" can be wrong for an ordinary lens (a 40-frame 960x540 orbit: bound 1452 px,
  // true 831). Then the error rises steeply from the bound on — no plateau — and holding the focal there builds
  // the whole model on it (0.08% centre error, distortion absorbing the rest). The data do determine the focal:
  // release it to bundle adjustment from here, as for any guess.
  if (r.best_factor == 1 && r.rms_at_start_px > 0 && r.rms_next_px > 1.2 * r.rms_at_start_px) {
    focal_fixed_ = focal_from_plateau_ = false;
    spdlog::info(
        "focal: the error rises from the scan's lower bound on ({:.3f} → {:.3f} px): no plateau, the focal "
        "is refined from here",
        r.rms_at_start_px, r.rms_next_px);
  }
  if (r.best_factor != 1 && !r.best.images.empty()) {
    rec_ = std::move(r.best);
    const auto& cam = rec_.cameras.begin()->second;
    narrow_field_ = narrow_field_ || 0.5 * std::hypot(cam.width, cam.height) / cam.f < opt_.narrow_field_max_radius;
    FilterPoints(nullptr);
  }
}

// Loop policy, one image: the candidates that see enough of the model (and, if they failed before, clearly more
// of it than then) are tried best-spread first; the first that registers is triangulated and locally adjusted.
GrowthStep ModelBuilder::RegisterNextImage() {
  std::vector<std::pair<double, uint32_t>> cands;
  for (uint32_t id : pool_) {
    if (rec_.images.count(id)) continue;
    double score = 0;
    const int vis = VisiblePoints(id, &score);
    if (vis < opt_.min_visible_points) {
      auto f = fail_reason_.find(id);
      if (f == fail_reason_.end() || f->second.kind == RegistrationFailure::Kind::kTooFewVisiblePoints)
        fail_reason_[id] = {RegistrationFailure::Kind::kTooFewVisiblePoints, vis, opt_.min_visible_points};
      continue;
    }
    // A frame that failed is retried only after the model offers it clearly more points.
    auto f = visible_at_failure_.find(id);
    if (f != visible_at_failure_.end() && (vis < 1.25 * f->second + 5 || trials_[id] >= opt_.max_registration_trials))
      continue;
    cands.emplace_back(-score, id);
  }
  if (cands.empty()) return GrowthStep::kNoCandidate;
  std::sort(cands.begin(), cands.end());
  for (const auto& [neg, id] : cands) {
    if (TryRegister(id)) {
      const int made = TriangulateImage(id);
      // A global adjustment due now covers the new image and its neighbours too: the local one would only
      // be repeated by it (while the model is small, both used to run after every image).
      if (!GlobalBundleAdjustDue()) LocalBundleAdjust(id);
      spdlog::debug("registered {} ({} images, +{} points)", images_.at(id)->name, rec_.images.size(), made);
      return GrowthStep::kRegistered;
    }
    ++trials_[id];
    visible_at_failure_[id] = VisiblePoints(id, nullptr);
  }
  return GrowthStep::kAllFailed;
}

void ModelBuilder::Grow() {
  GlobalBundleAdjust(false);
  while (RegisterNextImage() == GrowthStep::kRegistered) {
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
  if (static_cast<int>(rec_.images.size()) >= opt_.refine_principal_point_min_images) {
    bool any = false;
    if (focal_fixed_ && focal_from_plateau_ && TrySelfCalibration(IntrinsicGroup::kFocal)) {
      focal_fixed_ = false;
      any = true;
    }
    // Radial first: the principal point is tested on the model the final adjustment will keep.
    any = TryRadialSelfCalibration() || any;
    any = TrySelfCalibration(IntrinsicGroup::kPrincipalPoint) || any;
    // Then, when asked, the aspect (s_u; square pixels held), on the model with the principal point decided
    // (MapperOptions::self_calibrate_aspect says why not by default). Tangential distortion stays untested: with
    // the principal point free it trades against it beyond what the per-group covariance shows (fountain-P11:
    // rotation error 0.077° → 0.127°).
    if (opt_.self_calibrate_aspect) any = TrySelfCalibration(IntrinsicGroup::kAspect) || any;
    if (any) GlobalBundleAdjust(true);
  }
  UpdatePointErrors(&rec_);
}

// The largest model's tracks against those the matches allow (track_builder.h).
nlohmann::json TrackReport(const MapperInput& input, const std::map<uint32_t, size_t>& num_kp,
                           const std::vector<core::Reconstruction>& models) {
  const TrackSet tracks = BuildTracks(num_kp, input.pairs);
  nlohmann::json j = {{"union_find_tracks", tracks.tracks.size()},
                      {"union_find_links", tracks.num_links},
                      {"union_find_conflicts_cut", tracks.num_conflicts},
                      {"union_find_mean_length", tracks.MeanLength()},
                      {"union_find_mean_length_3_or_more_views", tracks.MeanLengthMultiView()},
                      {"definition",
                       "mean track length = observations / points of the model (as COLMAP reports it); union_find: "
                       "tracks of all verified matches, a link putting two keypoints of one image in a track cut"}};
  if (models.empty()) return j;
  const TrackCoverage c = MeasureTrackCoverage(tracks, models[0]);
  j["model_points"] = c.points;
  j["model_observations"] = c.observations;
  j["model_mean_track_length"] = c.points ? static_cast<double>(c.observations) / c.points : 0.0;
  j["union_find_tracks_touched"] = c.tracks_touched;
  j["keypoints_of_touched_tracks"] = c.keypoints_of_touched_tracks;
  j["keypoints_of_touched_tracks_held"] = c.held_of_touched_tracks;
  j["touched_tracks_split_over_points"] = c.tracks_split;
  return j;
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
    auto calibration = builder.self_calibration();
    for (const auto& [id, im] : rec.images) pool.erase(id);
    for (const auto& [id, why] : builder.fail_reasons())
      if (!reasons.count(id)) reasons[id] = why;
    if (static_cast<int>(rec.images.size()) < options.min_model_size) continue;
    spdlog::info("model {}: {} images, {} points", result.models.size(), rec.images.size(), rec.points.size());
    result.models.push_back(std::move(rec));
    result.self_calibration.push_back(std::move(calibration));
  }
  {  // largest first, each model with its self-calibration tests
    std::vector<size_t> order(result.models.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return result.models[a].images.size() > result.models[b].images.size();
    });
    MapperResult sorted;
    for (size_t i : order) {
      sorted.models.push_back(std::move(result.models[i]));
      sorted.self_calibration.push_back(std::move(result.self_calibration[i]));
    }
    result.models = std::move(sorted.models);
    result.self_calibration = std::move(sorted.self_calibration);
  }
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
                  {"tracks", TrackReport(input, num_kp, result.models)},
                  {"invalid_matches_skipped", graph.NumSkipped()},
                  {"models", result.models.size()},
                  {"relocalised_images", relocalised},
                  {"seconds",
                   {{"initial_pair", timings.init},
                    {"absolute_pose", timings.registration},
                    {"triangulation", timings.triangulation},
                    {"local_ba", timings.local_ba},
                    {"global_ba", timings.global_ba},
                    {"filtering", timings.filtering},
                    {"total", Seconds(start)}}}};
  return result;
}

}  // namespace fmv3d::sfm
