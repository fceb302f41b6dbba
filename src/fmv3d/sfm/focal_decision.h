// How the mapper decided a model's starting focal: known, or the two-view scan's verdict, and what the multi-view
// dolly-zoom scan did after it (focal_scan.h, dolly_zoom_scan.h). The report writes it as report/sparse.json's
// "focal_decision" (sparse_stage.cc).
#pragma once

#include <cstddef>
#include <optional>

namespace fmv3d::sfm {

enum class FocalDecisionKind {
  kNone,          // no decision recorded
  kKnown,         // the focal came with the camera (EXIF, calibration, sensor database)
  kDistorted,     // the scan's division model explained the matches: a wide lens, focal and distortion free
  kUndetermined,  // a flat curve: the shortest candidate held as a lower bound until the final test
  kPlateau,       // a supported knee: a lower bound, held until the final test
  kMinimum,       // a minimum: a start that bundle adjustment refines
  kRestart,       // a second mapping, started at the focal the first one refined to (no scan)
};
// "known", "distorted", "undetermined", "plateau", "minimum", "restart" (kNone: "none").
const char* FocalDecisionName(FocalDecisionKind kind);
// A focal the scans chose from a guess alone (a minimum, plateau or flat curve): what a second mapping may start
// from elsewhere. Not a stated focal, a wide lens's start (the scan's distortion as well) nor a restart itself.
bool FocalMayRestart(FocalDecisionKind kind);

struct DollyZoomDecision {
  size_t images = 0;           // images of the model when it ran
  double factor = 1;           // best focal / start
  double focal_px = 0;         // the best focal
  double shortest_factor = 1;  // the shortest focal tried / start
  bool released = false;       // the focal was freed to bundle adjustment from here
  double seconds = 0;
};

// A guessed focal that the first mapping moved far from where it started: the model grew under a wrong focal
// (early poses and points fitted to it), so the images were mapped again from the refined focal.
struct FocalRestart {
  double first_start_px = 0;  // where the first mapping's focal started (the scans' choice)
  double first_final_px = 0;  // where its adjustments took it: the second mapping's start
  double change = 0;          // |final / start − 1|
  size_t first_images = 0;    // the first mapping's largest model (where it stopped, when early)
  double first_reprojection_px = 0;
  // The first mapping stopped growing as soon as its focal had moved (ModelBuilder::StopWhenFocalMoves): what it
  // would have added under the wrong focal is mapped again anyway. The second mapping is then kept.
  bool early = false;
  bool kept = false;   // the second mapping was kept (it registers at least as many images)
  double seconds = 0;  // the second mapping
};

struct FocalDecision {
  FocalDecisionKind kind = FocalDecisionKind::kNone;
  double known_focal_px = 0;  // kKnown
  // The two-view scan (every kind but kKnown and kNone).
  double guess_px = 0;
  size_t pairs = 0;
  double two_view_focal_px = 0;
  double pinhole_best_px2 = 0, division_best_px2 = 0;
  double division_excess_of_half_diagonal = 0;
  double division_kappa = 0;
  double initial_k1 = 0, initial_k2 = 0;
  size_t candidates = 0;
  double seconds = 0, division_seconds = 0;
  std::optional<DollyZoomDecision> dolly_zoom;
  std::optional<FocalRestart> restart;  // set on the kept model's decision when the images were mapped twice
};

}  // namespace fmv3d::sfm
