// Multi-view focal scan for a model whose two-view scan (focal_scan.h) only gave a lower bound.
// Lengthening the focal by k while moving every camera back along its axis by (k − 1) times its median depth
// keeps the projections almost unchanged (a dolly zoom), so each candidate starts near its own optimum and a
// short BA with the focal held at the candidate measures how well that focal explains all views together — the
// perspective effects too small to see in one pair add up over the model.
#pragma once

#include <string>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace fmv3d::sfm {

struct DollyZoomScanOptions {
  double max_factor = 64;  // candidates: the model's focal times 1, √2, 2, ... up to this
  // ... and times 1/√2, 1/2, ... down to this (1: longer focals only); the shorter scan stops once the error has
  // risen to rise_stop times the lowest it found there.
  double min_factor = 1;
  double rise_stop = 1.5;
  // Each candidate's rms is compared with the others': a fixed budget, independent of the mapper's BAs.
  int max_iterations = 20;
  double function_tolerance = 1e-6;
};

struct DollyZoomScanResult {
  double best_factor = 1;      // 1: the starting focal explains the views best; < 1: a shorter one
  core::Reconstruction best;   // the model at the best candidate (empty when no BA succeeded)
  double rms_at_start_px = 0;  // rms at the starting focal ...
  double rms_next_px = 0;      // ... and at the next candidate (0 when it failed)
  double rms_best_px = 0;      // at the best candidate ...
  double rms_longest_px = 0;   // ... and at the longest that succeeded
  double rms_shorter_px = 0;   // at the first shorter candidate (0 when none was tried or it failed)
  std::string curve;           // "focal:rms" per longer candidate (the start included), for the log
  std::string curve_shorter;   // ... and per shorter candidate
};

// options: the BA of each candidate (its focal and distortion flags are overridden: both held).
DollyZoomScanResult ScanFocalDollyZoom(const core::Reconstruction& rec, const BundleAdjustmentConfig& config,
                                       BundleAdjustmentOptions options, const DollyZoomScanOptions& scan);

}  // namespace fmv3d::sfm
