#include "fmv3d/sfm/dolly_zoom_scan.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace fmv3d::sfm {

namespace {

// Scales the focal by dk and moves every camera along its axis by (dk − 1) times its median depth: the
// projections stay almost unchanged, so the candidate starts near its own optimum.
void DollyZoom(core::Reconstruction* m, double dk) {
  for (auto& [cid, cam] : m->cameras) cam.f *= dk;
  for (auto& [iid, im] : m->images) {
    std::vector<double> depths;
    for (int64_t pid : im.point3d_ids)
      if (pid != core::kNoPoint3D)
        depths.push_back(im.pose.Transform(m->points.at(static_cast<uint64_t>(pid)).xyz).z());
    if (depths.empty()) continue;
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    im.pose.t.z() += (dk - 1) * depths[depths.size() / 2];
  }
}

}  // namespace

DollyZoomScanResult ScanFocalDollyZoom(const core::Reconstruction& rec, const BundleAdjustmentConfig& config,
                                       BundleAdjustmentOptions o, const DollyZoomScanOptions& scan) {
  DollyZoomScanResult r;
  o.refine_focal = false;
  o.refine_k1 = o.refine_k2 = false;  // distortion would absorb the perspective the scan measures
  o.max_iterations = scan.max_iterations;
  o.function_tolerance = scan.function_tolerance;
  double best_rms = std::numeric_limits<double>::infinity();
  auto keep_if_best = [&](double k, const core::Reconstruction& m, double rms) {
    if (rms >= best_rms) return;
    best_rms = r.rms_best_px = rms;
    r.best_factor = k;
    r.best = m;
  };
  // Continuation: each candidate starts from the previous one's optimum (a step of √2), so the BA follows the
  // valley even when the first model (built at the lower bound) is far from affine.
  core::Reconstruction m = rec, at_start;
  const double step = std::sqrt(2.0);
  for (double k = 1; k <= scan.max_factor * 1.0001; k *= step) {
    DollyZoom(&m, k == 1 ? 1 : step);
    const auto sm = BundleAdjust(&m, config, o);
    if (!sm.success) continue;
    r.curve += fmt::format(" {:.0f}:{:.4f}", m.cameras.begin()->second.f, sm.final_rms_px);
    r.rms_longest_px = sm.final_rms_px;
    if (k == 1) {
      r.rms_at_start_px = sm.final_rms_px;
      at_start = m;
    } else if (r.rms_next_px == 0) {
      r.rms_next_px = sm.final_rms_px;
    }
    keep_if_best(k, m, sm.final_rms_px);
  }
  // Shorter focals, from the start's optimum down to min_factor: the start is only as good as the two-view scan
  // that chose it, and a knee read from a noisy curve can sit far beyond the focal the views determine. Stops
  // once the error has clearly risen past a minimum below the start.
  if (r.rms_at_start_px <= 0 || scan.min_factor >= 1) return r;
  m = std::move(at_start);
  double shortest_best = std::numeric_limits<double>::infinity();
  for (double k = 1 / step; k >= scan.min_factor * 0.9999; k /= step) {
    DollyZoom(&m, 1 / step);
    const auto sm = BundleAdjust(&m, config, o);
    if (!sm.success) break;  // the continuation has lost the valley: nothing shorter is comparable
    r.curve_shorter += fmt::format(" {:.0f}:{:.4f}", m.cameras.begin()->second.f, sm.final_rms_px);
    if (r.rms_shorter_px == 0) r.rms_shorter_px = sm.final_rms_px;
    shortest_best = std::min(shortest_best, sm.final_rms_px);
    keep_if_best(k, m, sm.final_rms_px);
    if (sm.final_rms_px > scan.rise_stop * shortest_best) break;
  }
  return r;
}

}  // namespace fmv3d::sfm
