// The model builder's start (model_builder.h): the focal guess checked by a two-view scan, then the initial
// pair, chosen by passes that relax the angle and planarity demands until a pair triangulates.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "fmv3d/sfm/focal_scan.h"
#include "fmv3d/sfm/model_builder.h"

namespace fmv3d::sfm::mapper {

void ModelBuilder::ChooseFocal(const std::vector<InitialPairCandidate>& cands) {
  if (cands.empty()) return;
  const uint32_t cid = images_.at(cands[0].pair->image_id1)->camera_id;
  const MapperCamera& mc = input_.cameras.at(cid);
  auto narrow = [&](double f) {
    // Radial distortion moves a point by ~k·r³: at r = half-diagonal / f < 0.1 it is far below the noise for any
    // plausible k, so refining k1/k2 there only lets them wander.
    return 0.5 * std::hypot(mc.camera.width, mc.camera.height) / f < opt_.narrow_field_max_radius;
  };
  if (mc.focal_known) {
    focal_decision_ = FocalDecision{};
    focal_decision_.kind = FocalDecisionKind::kKnown;
    focal_decision_.known_focal_px = mc.camera.f;
    focal_fixed_ = opt_.fix_known_focal;
    narrow_field_ = narrow(mc.camera.f);
    return;
  }
  if (const auto it = focal_start_.find(cid); it != focal_start_.end()) {
    init_focal_scale_ = it->second / mc.camera.f;
    focal_fixed_ = focal_from_plateau_ = false;
    narrow_field_ = narrow(it->second);
    focal_decision_ = FocalDecision{};
    focal_decision_.kind = FocalDecisionKind::kRestart;
    focal_decision_.guess_px = mc.camera.f;
    focal_decision_.two_view_focal_px = it->second;
    spdlog::info("focal: mapping again from the first mapping's refined focal, {:.1f} px ({:.2f} x the guess)",
                 it->second, init_focal_scale_);
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
  const auto start = Clock::now();
  const FocalScanResult r = ScanFocal(mc.camera, pairs, fo);
  const double seconds = Seconds(start);
  init_focal_scale_ = r.focal / mc.camera.f;
  focal_fixed_ = focal_from_plateau_ = r.plateau;
  narrow_field_ = narrow(r.focal);
  // The lens the scan found starts the model; k1, k2 stay free in bundle adjustment (tested at the end).
  if (r.division != 0) init_distortion_ = {r.k1, r.k2};
  std::string curve, cells;
  for (size_t i = 0; i < r.focals.size(); ++i) curve += fmt::format(" {:.0f}:{:.3f}", r.focals[i], r.scores[i]);
  for (const auto& c : r.division_cells) cells += fmt::format(" {:.0f}/{:.3f}:{:.3f}", c[0], c[1], c[2]);
  spdlog::info(
      "focal scan on {} pairs: {:.1f} px ({:.2f} x the guess){}{} ({:.1f} s)", pairs.size(), r.focal, init_focal_scale_,
      r.division != 0 ? fmt::format(", {} distortion: division κ {:.3f} (k1 {:.3f}, k2 {:.3f}) explains the matches at "
                                    "{:.3f} px² vs the pinhole's {:.3f} (removes {:.2g} of the half-diagonal)",
                                    r.division < 0 ? "barrel" : "pincushion", r.division, r.k1, r.k2, r.division_best,
                                    r.pinhole_best, r.division_excess)
      : r.undetermined ? ", a flat curve: the shortest candidate as a lower bound, held until the final test"
      : r.plateau      ? ", plateau: a lower bound, held until the final test"
                       : "",
      narrow_field_ ? ", narrow field: distortion fixed" : "", seconds);
  spdlog::debug("focal scan (f: px²):{}", curve);
  spdlog::debug("focal scan with a division model (f/κ: px²):{}", cells);
  focal_decision_ = FocalDecision{};
  FocalDecision& d = focal_decision_;
  d.kind = r.division != 0  ? FocalDecisionKind::kDistorted
           : r.undetermined ? FocalDecisionKind::kUndetermined
           : r.plateau      ? FocalDecisionKind::kPlateau
                            : FocalDecisionKind::kMinimum;
  d.guess_px = mc.camera.f;
  d.pairs = pairs.size();
  d.two_view_focal_px = r.focal;
  d.pinhole_best_px2 = r.pinhole_best;
  d.division_best_px2 = r.division_best;
  d.division_excess_of_half_diagonal = r.division_excess;
  d.division_kappa = r.division;
  d.initial_k1 = r.k1;
  d.initial_k2 = r.k2;
  d.candidates = r.focals.size() + r.division_cells.size();
  d.seconds = seconds;
  d.division_seconds = r.division_seconds;
}

core::Camera ModelBuilder::InitialCamera(uint32_t camera_id) const {
  core::Camera cam = input_.cameras.at(camera_id).camera;
  if (init_distortion_) std::tie(cam.k1, cam.k2) = *init_distortion_;
  return cam;
}

bool ModelBuilder::TryInitialPair(const InitialPairCandidate& c) {
  rec_ = core::Reconstruction();
  const auto& pair = *c.pair;
  AddImage(pair.image_id1, core::Pose());
  AddImage(pair.image_id2, c.pose2);
  for (auto& [cid, cam] : rec_.cameras) {
    cam.f *= c.focal_scale;
    if (init_distortion_) std::tie(cam.k1, cam.k2) = *init_distortion_;
  }
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
  std::vector<InitialPairCandidate> cands;
  for (const auto& p : input_.pairs)
    if (pool_.count(p.image_id1) && pool_.count(p.image_id2) &&
        static_cast<int>(p.inliers.size()) >= opt_.init_min_inliers) {
      InitialPairCandidate c;
      c.pair = &p;
      cands.push_back(c);
    }
  std::stable_sort(cands.begin(), cands.end(), [](const InitialPairCandidate& a, const InitialPairCandidate& b) {
    return a.pair->inliers.size() > b.pair->inliers.size();
  });
  if (static_cast<int>(cands.size()) > opt_.init_max_candidates) cands.resize(opt_.init_max_candidates);
  ChooseFocal(cands);
  for (auto& c : cands) {
    const MapperImage& im1 = *images_.at(c.pair->image_id1);
    const MapperImage& im2 = *images_.at(c.pair->image_id2);
    EvaluateInitialPair(im1, im2, InitialCamera(im1.camera_id), InitialCamera(im2.camera_id), init_focal_scale_, opt_,
                        &c);
  }
  // Strict first (enough angle, not planar), then relax the angle and finally accept planar pairs.
  const std::vector<std::pair<double, bool>> passes = {
      {opt_.init_min_tri_angle_deg, false},     {opt_.init_min_tri_angle_deg / 2, false},
      {opt_.init_min_tri_angle_deg / 4, false}, {opt_.init_min_tri_angle_deg / 2, true},
      {opt_.init_min_tri_angle_deg / 8, true},  {opt_.init_min_tri_angle_deg / 32, true}};
  std::set<const features::VerifiedPair*> tried;
  for (const auto& [min_angle, allow_planar] : passes) {
    std::vector<const InitialPairCandidate*> ok;
    for (const auto& c : cands)
      if (c.valid && c.median_angle_deg >= min_angle && (allow_planar || c.h_ratio <= opt_.init_max_h_ratio) &&
          c.num_good >= opt_.init_min_inliers / 2 && !tried.count(c.pair))
        ok.push_back(&c);
    std::stable_sort(ok.begin(), ok.end(), [](const InitialPairCandidate* a, const InitialPairCandidate* b) {
      return a->num_good > b->num_good;
    });
    for (const InitialPairCandidate* c : ok) {
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

}  // namespace fmv3d::sfm::mapper
