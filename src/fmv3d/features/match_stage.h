// The `fmv3d match` stage: pair selection, descriptor matching and geometric verification of every pair.
// Reads WS/frames/frames.json and WS/features/*.feat; writes WS/matches/matches.bin (all verified pairs,
// see feature_io.h) and WS/matches/matches.json (pairs tried / verified, inlier counts per pair, timing), and
// WS/matches/automatic.* (every pair's automatic result, read back by the next run where its inputs are unchanged).
// Memory: the pairs are written in pair order as they are verified (MatchPairsInFlight() results held at once), the
// last run's results are read back pair by pair, and matches.bin is written from automatic.bin pair by pair with
// the operator's edits, so the stage holds the descriptor window, per-pair summaries and a few pairs' inliers.
//
// Calibrated vs uncalibrated: E is estimated with each camera's prior intrinsics from frames.json. When the
// prior is trusted (recorded and not a guess), a pair whose E explains ≥ 95% of the F inliers is
// kCalibrated and keeps E's inliers. With a guessed prior the pair keeps F's inliers (F does not depend on the
// guess) and is only labelled kCalibrated when the guessed E still explains ≥ 95% of them (the guess is then
// good enough for this pair); its relative pose (R, t) is filled in either case when E gives one.
//
// The operator's tie points (WS/manual/tiepoints.json, or MatchStageOptions::tiepoints_file) are added after the
// automatic matching (features/manual_matches.h): WS/matches/manual.json holds the keypoints they append, and
// matches.json "manual" what was added, found and deleted, and the tie points that disagree with an automatic F.
#pragma once

#include <filesystem>
#include <optional>

#include "fmv3d/core/error.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/manual_matches.h"
#include "fmv3d/features/matcher.h"
#include "fmv3d/features/pairs.h"
#include "fmv3d/geometry/two_view.h"

namespace fmv3d::features {

struct MatchStageOptions {
  PairOptions pairs;
  MatchOptions match;
  geometry::TwoViewOptions verify;
  ManualMatchOptions manual;
  std::optional<std::filesystem::path> tiepoints_file;  // default: WS/manual/tiepoints.json when it exists
  bool use_tiepoints = true;
  // Read back the pairs whose inputs are unchanged since the last run (match_cache.h); false: match every pair.
  bool reuse = true;
  // Memory for the descriptors and search structures of the images being matched: as many images are held as
  // fit (at ~1.4 KB per keypoint), so a video of thousands of frames is matched in a bounded window.
  double max_memory_mb = 2048;
  void Check() const {
    if (!(max_memory_mb > 0)) throw Error("match: --max-memory must be > 0 MB");
    manual.Check();
    pairs.Check();
    match.Check();
    verify.Check();
  }
};

struct MatchStageStats {
  size_t images = 0, pairs_tried = 0, pairs_verified = 0, loop_closure_pairs = 0;
  size_t pairs_reused = 0;  // of pairs_tried: read back from the last run's matches/automatic.* (match_cache.h)
  size_t calibrated = 0, uncalibrated = 0, planar_or_rotation = 0;
  double seconds_total = 0, seconds_load = 0, seconds_pairs = 0;
  double cpu_seconds_match = 0, cpu_seconds_verify = 0;  // summed over threads
  size_t descriptor_cache_capacity = 0;                  // images the memory budget holds at once
  size_t peak_cached_images = 0;
  size_t descriptor_loads = 0;  // feature files read for matching (more than `images` when some were evicted)
  size_t peak_pairs_held = 0;   // pair results held at once between matching and writing: <= MatchPairsInFlight()
};

// Pair results the match stage holds at most (matched but not yet written, since a pair before them is not done):
// a few per thread, whatever the pair count.
size_t MatchPairsInFlight();

MatchStageStats RunMatchStage(const core::Workspace& workspace, const MatchStageOptions& options);

}  // namespace fmv3d::features
