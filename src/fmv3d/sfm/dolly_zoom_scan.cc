#include "fmv3d/sfm/dolly_zoom_scan.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace fmv3d::sfm {

DollyZoomScanResult ScanFocalDollyZoom(const core::Reconstruction& rec, const BundleAdjustmentConfig& config,
                                       BundleAdjustmentOptions o, const DollyZoomScanOptions& scan) {
  DollyZoomScanResult r;
  o.refine_focal = false;
  o.refine_k1 = o.refine_k2 = false;  // distortion would absorb the perspective the scan measures
  o.max_iterations = scan.max_iterations;
  o.function_tolerance = scan.function_tolerance;
  double best_rms = std::numeric_limits<double>::infinity();
  // Continuation: each candidate starts from the previous one's optimum (a step of √2), so the BA follows the
  // valley even when the first model (built at the lower bound) is far from affine.
  core::Reconstruction m = rec;
  const double step = std::sqrt(2.0);
  for (double k = 1; k <= scan.max_factor * 1.0001; k *= step) {
    const double dk = k == 1 ? 1 : step;
    for (auto& [cid, cam] : m.cameras) cam.f *= dk;
    for (auto& [iid, im] : m.images) {
      std::vector<double> depths;
      for (int64_t pid : im.point3d_ids)
        if (pid != core::kNoPoint3D)
          depths.push_back(im.pose.Transform(m.points.at(static_cast<uint64_t>(pid)).xyz).z());
      if (depths.empty()) continue;
      std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
      im.pose.t.z() += (dk - 1) * depths[depths.size() / 2];
    }
    const auto sm = BundleAdjust(&m, config, o);
    if (!sm.success) continue;
    r.curve += fmt::format(" {:.0f}:{:.4f}", m.cameras.begin()->second.f, sm.final_rms_px);
    r.rms_longest_px = sm.final_rms_px;
    if (k == 1)
      r.rms_at_start_px = sm.final_rms_px;
    else if (r.rms_next_px == 0)
      r.rms_next_px = sm.final_rms_px;
    if (sm.final_rms_px < best_rms) {
      best_rms = r.rms_best_px = sm.final_rms_px;
      r.best_factor = k;
      r.best = m;
    }
  }
  return r;
}

}  // namespace fmv3d::sfm
