// The model builder's growth (model_builder.h): registration of the next image, re-registration of images at
// wrong poses, local and global bundle adjustment, and the loop policy that orders them.
#include "fmv3d/sfm/model_builder.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "fmv3d/geometry/absolute_pose.h"

namespace fmv3d::sfm::mapper {

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
int ModelBuilder::ReRegisterWrongPoses() {
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
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.variable_images.insert(image_id);
  // Neighbours: the registered images sharing most points with the new one.
  for (uint32_t id : ImagesSharingMostPoints(rec_, image_id, opt_.local_ba_num_images - 1))
    cfg.variable_images.insert(id);
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

void ModelBuilder::GlobalBaSetup(bool final_pass, BundleAdjustmentConfig* cfg, BundleAdjustmentOptions* o) const {
  *cfg = NewBaConfig();
  cfg->gauge_image1 = gauge1_;
  cfg->gauge_image2 = gauge2_;
  *o = BaOptions();
  // Intermediate adjustments only need to be near the optimum (the next image and the final pass refine further).
  o->max_iterations = opt_.global_ba_max_iterations;
  o->function_tolerance = 1e-5;
  if (final_pass) {
    o->function_tolerance = opt_.final_ba_function_tolerance;
    o->max_iterations = opt_.final_ba_max_iterations;
  }
}

BundleAdjustmentSummary ModelBuilder::GlobalBundleAdjust(bool final_pass) {
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg;
  BundleAdjustmentOptions o;
  GlobalBaSetup(final_pass, &cfg, &o);
  BundleAdjustmentSummary s = BundleAdjust(&rec_, cfg, o);
  ++num_global_ba_;
  t_->global_ba += Seconds(start);
  spdlog::debug("global BA ({} images, {} points): rms {:.3f} → {:.3f} px in {} iterations, {:.2f} s",
                rec_.images.size(), rec_.points.size(), s.initial_rms_px, s.final_rms_px, s.num_iterations, s.seconds);
  FilterPoints(nullptr);
  images_at_last_global_ = rec_.images.size();
  return s;
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

size_t ModelBuilder::CompleteTracksByProjection() {
  if (!opt_.guided_completion) return 0;
  const auto start = Clock::now();
  std::map<uint32_t, const features::Descriptors*> descriptors;
  for (const auto& [id, im] : rec_.images) {
    const features::Descriptors* d = images_.at(id)->descriptors;
    if (d && static_cast<size_t>(d->rows()) == im.points2d.size()) descriptors[id] = d;
  }
  const KeypointScales scales = Scales();
  if (descriptors.size() < 2) return 0;
  std::map<uint32_t, std::set<uint32_t>> covisible;
  for (const auto& p : input_.pairs)
    if (!p.inliers.empty() && rec_.images.count(p.image_id1) && rec_.images.count(p.image_id2)) {
      covisible[p.image_id1].insert(p.image_id2);
      covisible[p.image_id2].insert(p.image_id1);
    }
  GuidedCompletionOptions o;
  o.max_error_px = opt_.tri_max_error_px;
  o.false_accept_rate = opt_.guided_completion_false_accept_rate;
  o.ratio = opt_.guided_completion_ratio;
  const size_t obs_before = [&] {
    size_t n = 0;
    for (const auto& [pid, p] : rec_.points) n += p.track.size();
    return n;
  }();
  GuidedCompletionStats s = sfm::CompleteTracksByProjection(&rec_, descriptors, covisible, o, scales);
  guided_added_ = std::move(s.added);
  t_->triangulation += Seconds(start);
  spdlog::info(
      "mapper: guided completion added {} observations to {} ({} conflicts; search radius {:.2f} px median, σ {:.2f} "
      "px; descriptor bound {:.0f})",
      s.accepted, obs_before, s.conflicts, s.median_radius_px, s.sigma_px, s.descriptor_bound);
  const size_t accepted = s.accepted;
  GuidedCompletionPass pass;
  pass.observations_before = obs_before;
  pass.options = o;
  pass.stats = std::move(s);
  pass.stats.added.clear();
  pass.seconds = Seconds(start);
  guided_completion_.push_back(std::move(pass));
  return accepted;
}

KeypointScales ModelBuilder::Scales() const {
  KeypointScales scales;
  for (const auto& [id, im] : rec_.images)
    if (!images_.at(id)->scales.empty()) scales[id] = &images_.at(id)->scales;
  return scales;
}

size_t ModelBuilder::PruneGuidedAdditions() {
  if (!opt_.guided_completion_prune || guided_added_.empty() || guided_completion_.empty()) return 0;
  GuidedCompletionOptions o;
  o.max_error_px = opt_.tri_max_error_px;
  const size_t removed = RemoveAdditionsThatDoNotFit(&rec_, guided_added_, o, Scales());
  guided_added_.clear();
  guided_completion_.back().removed_after_adjustment = removed;
  spdlog::info("mapper: {} guided additions removed after the adjustment (outside their search bound)", removed);
  return removed;
}

void ModelBuilder::RecordGrowthFocal() {
  growth_focal_.clear();
  if (!FocalMayRestart(focal_decision_.kind)) return;
  for (const auto& [cid, cam] : rec_.cameras)
    if (!input_.cameras.at(cid).focal_known) growth_focal_[cid] = cam.f;
}

double ModelBuilder::FocalMove(const core::Reconstruction& rec, FocalStop* stop) const {
  *stop = FocalStop{};
  for (const auto& [cid, start] : growth_focal_) {
    const double f = rec.cameras.at(cid).f;
    stop->focal_px[cid] = f;
    const double moved = std::abs(f / start - 1);
    if (moved > stop->change) {
      stop->change = moved;
      stop->start_px = start;
      stop->final_px = f;
    }
  }
  return stop->change;
}

bool ModelBuilder::StopForFocal() {
  if (!(stop_focal_change_ > 0) || focal_fixed_ || growth_focal_.empty() ||
      static_cast<int>(rec_.images.size()) < stop_focal_min_images_)
    return false;
  FocalStop stop;
  const bool first_check = !focal_stop_checked_;
  if (FocalMove(rec_, &stop) <= stop_focal_change_ && !first_check) return false;
  focal_stop_checked_ = true;
  // An intermediate adjustment stops after a few iterations, part of the way. The first check, and any that sees
  // the move, reads the focal from a converged adjustment of a copy (the model grows on unchanged when it stays).
  const auto start = Clock::now();
  core::Reconstruction converged = rec_;
  BundleAdjustmentConfig cfg;
  BundleAdjustmentOptions o;
  GlobalBaSetup(/*final_pass=*/true, &cfg, &o);
  BundleAdjust(&converged, cfg, o);
  t_->global_ba += Seconds(start);
  FocalMove(converged, &stop);
  spdlog::debug("mapper: focal {:.1f}% from its growth start ({:.1f} → {:.1f} px) at {} images, converged ({:.1f} s)",
                100 * stop.change, stop.start_px, stop.final_px, rec_.images.size(), Seconds(start));
  if (stop.change <= stop_focal_change_) return false;
  spdlog::info("mapper: the focal moved {:.1f}% ({:.1f} → {:.1f} px) with {} images registered: growth stops here",
               100 * stop.change, stop.start_px, stop.final_px, rec_.images.size());
  rec_ = std::move(converged);
  focal_stop_ = std::move(stop);
  return true;
}

void ModelBuilder::Grow() {
  GlobalBundleAdjust(false);
  RecordGrowthFocal();
  while (RegisterNextImage() == GrowthStep::kRegistered) {
    if (focal_from_plateau_ && !dolly_done_ && static_cast<int>(rec_.images.size()) >= opt_.focal_dolly_min_images) {
      DollyZoomFocalScan();
      RecordGrowthFocal();
      GlobalBundleAdjust(false);
      Retriangulate();
      if (StopForFocal()) return;
      continue;
    }
    if (GlobalBundleAdjustDue()) {
      GlobalBundleAdjust(false);
      Retriangulate();
      if (StopForFocal()) return;
    }
  }
  // Final polish: retriangulate with the refined cameras, then a tight global BA.
  GlobalBundleAdjust(false);
  if (opt_.relocalise && (num_relocalised_ = ReRegisterWrongPoses()) > 0) GlobalBundleAdjust(false);
  Retriangulate();
  CompleteTracksByProjection();
  GlobalBundleAdjust(true);
  // The adjusted points and cameras project more exactly: a second pass finds what the first one's radius missed.
  // Each pass's additions that the adjustment after it does not explain are dropped again, and the model
  // adjusted without them.
  const size_t pruned = PruneGuidedAdditions();
  if (CompleteTracksByProjection() > 0 || pruned > 0) GlobalBundleAdjust(true);
  if (PruneGuidedAdditions() > 0) GlobalBundleAdjust(true);
  if (static_cast<int>(rec_.images.size()) >= opt_.refine_principal_point_min_images) {
    bool any = false;
    if (focal_fixed_ && focal_from_plateau_ && TrySelfCalibration(IntrinsicGroup::kFocal)) {
      focal_fixed_ = false;
      any = true;
    }
    // Radial first: the principal point is tested on the model the final adjustment will keep.
    any = TryRadialSelfCalibration() || any;
    // The radial terms are not asked again once the principal point is freed: on an orbit the freed point sits on a
    // weakly determined focal–v0 line, and re-deciding k1/k2 there only moved it along that line (better on one
    // off-centre orbit, worse on another and on fountain-P11: bench/results/pp10.md).
    any = TrySelfCalibration(IntrinsicGroup::kPrincipalPoint) || any;
    // Then, when asked, the aspect (s_u; square pixels held), on the model with the principal point decided
    // (MapperOptions::self_calibrate_aspect says why not by default). Tangential distortion stays untested: with
    // the principal point free it trades against it beyond what the per-group covariance shows (fountain-P11:
    // rotation error 0.077° → 0.127°).
    if (opt_.self_calibrate_aspect) any = TrySelfCalibration(IntrinsicGroup::kAspect) || any;
    if (any) GlobalBundleAdjust(true);
  }
  DescribeIntrinsicsPosterior();
  UpdatePointErrors(&rec_);
}

}  // namespace fmv3d::sfm::mapper
