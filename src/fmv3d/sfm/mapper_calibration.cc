// The model builder's final self-calibration tests and the telephoto dolly-zoom focal scan (model_builder.h).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "fmv3d/sfm/dolly_zoom_scan.h"
#include "fmv3d/sfm/focal_scan.h"
#include "fmv3d/sfm/model_builder.h"

namespace fmv3d::sfm::mapper {

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

// The covariance at the final adjustment's optimum (the model is converged: no further adjustment), every free
// intrinsic at once. The tests' σ above are those of each group's fit on the Gaussian core; this is what the
// cameras handed on carry.
void ModelBuilder::DescribeIntrinsicsPosterior() {
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  const BundleAdjustmentOptions o = BaOptions();
  const BundleAdjustmentSummary s = IntrinsicsCovarianceAt(rec_, cfg, o);
  t_->global_ba += Seconds(start);
  posterior_.clear();
  for (const auto& [cid, cam] : rec_.cameras) {
    const auto cov = s.intrinsics_covariance.find(cid);
    IntrinsicsPosterior p =
        DescribePosterior(cam, FreeIntrinsics(o), cov == s.intrinsics_covariance.end() ? nullptr : &cov->second,
                          opt_.weak_intrinsic_corner_px);
    p.camera_id = cid;
    std::string figures;
    for (const auto& u : p.parameters)
      figures += fmt::format(" {} {:.6g} ± {:.3g} ({:.2f} px at the corner{})", IntrinsicName(u.parameter), u.value,
                             u.sigma, u.corner_sigma_px, u.weak ? ", weak" : "");
    if (!p.determined && !p.parameters.empty())
      spdlog::warn("camera {}: the free intrinsics are not all determined by the data (rank-deficient)", cid);
    else if (!p.parameters.empty())
      spdlog::info("camera {} posterior (1σ):{}; least determined combination ±{:.2f} px at the corner ({:.2f} s)", cid,
                   figures, p.weakest_corner_sigma_px, Seconds(start));
    for (const auto& u : p.parameters)
      if (u.weak)
        spdlog::warn("camera {}: {} is weakly determined on these images: ±{:.3g} (1σ), {:.2f} px at the corner", cid,
                     IntrinsicName(u.parameter), u.sigma, u.corner_sigma_px);
    posterior_.push_back(std::move(p));
  }
}

void ModelBuilder::DollyZoomFocalScan() {
  dolly_done_ = true;
  const auto start = Clock::now();
  BundleAdjustmentConfig cfg = NewBaConfig();
  cfg.gauge_image1 = gauge1_;
  cfg.gauge_image2 = gauge2_;
  DollyZoomScanOptions so;
  so.max_factor = opt_.focal_dolly_max_factor;
  // Shorter focals down to the two-view scan's shortest candidate: the start is that scan's reading, and a knee
  // read from a noisy curve can be far too long (a 100-frame orbit: 64x the guess, 89x the true focal).
  const uint32_t cid = rec_.cameras.begin()->first;
  const double shortest = input_.cameras.at(cid).camera.f * FocalScanOptions().min_factor;
  so.min_factor = std::min(1.0, shortest / rec_.cameras.begin()->second.f);
  DollyZoomScanResult r = ScanFocalDollyZoom(rec_, cfg, BaOptions(), so);
  t_->global_ba += Seconds(start);
  spdlog::info("focal dolly-zoom scan on {} images: x{:.3g} → {:.1f} px ({:.1f} s); rms px by focal:{}{}",
               rec_.images.size(), r.best_factor, r.best.cameras.empty() ? 0.0 : r.best.cameras.begin()->second.f,
               Seconds(start), r.curve, r.curve_shorter.empty() ? "" : "; shorter:" + r.curve_shorter);
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
  // A best focal beyond the start with the error rising again towards the longest is a minimum the views
  // determine, not the knee of a plateau (an orbit whose two-view curve was flat): refined from here.
  if (r.best_factor > 1 && r.rms_longest_px > 1.2 * r.rms_best_px) {
    focal_fixed_ = focal_from_plateau_ = false;
    spdlog::info("focal: the error rises again beyond {:.1f} px ({:.3f} → {:.3f} px): a minimum, refined from here",
                 r.best.cameras.begin()->second.f, r.rms_best_px, r.rms_longest_px);
  }
  // A shorter focal explains the views better than the start: the two-view "bound" was none, and the views
  // determine the focal (the error rises again towards the start): refined from the best.
  if (r.best_factor < 1) {
    focal_fixed_ = focal_from_plateau_ = false;
    spdlog::info(
        "focal: the views prefer {:.1f} px to the two-view scan's bound ({:.3f} vs {:.3f} px): not a bound, "
        "refined from here",
        r.best.cameras.begin()->second.f, r.rms_best_px, r.rms_at_start_px);
  }
  DollyZoomDecision& d = focal_decision_.dolly_zoom.emplace();
  d.images = rec_.images.size();
  d.factor = r.best_factor;
  d.focal_px = r.best.cameras.empty() ? 0.0 : r.best.cameras.begin()->second.f;
  d.shortest_factor = so.min_factor;
  d.released = !focal_fixed_;
  d.seconds = Seconds(start);
  if (r.best_factor != 1 && !r.best.images.empty()) {
    rec_ = std::move(r.best);
    const auto& cam = rec_.cameras.begin()->second;
    // The field the start was judged by changed with the focal (narrower, or wider again below the start).
    narrow_field_ = 0.5 * std::hypot(cam.width, cam.height) / cam.f < opt_.narrow_field_max_radius;
    FilterPoints(nullptr);
  }
}

}  // namespace fmv3d::sfm::mapper
