// Incremental structure-from-motion (COLMAP's shape, our code):
//   1. tracks from the verified pairs (tracks.h);
//   2. initial pair: many inliers, enough triangulation angle, not homography-dominated — relative pose from
//      the essential matrix, two-view triangulation, BA;
//   3. repeat: next-best view (most visible triangulated points, well spread over the image) → absolute pose
//      (P3P RANSAC + refinement) → triangulate the tracks it completes (multi-view DLT with angle and
//      reprojection checks) → local BA → outlier filtering; global BA (+ re-triangulation and track completion)
//      whenever the model has grown by a fixed ratio; frames that failed are retried once the model has grown;
//   4. when no more images register, a new model starts from the remaining images; models are returned
//      largest first.
// Intrinsics: one core::Camera per camera id (shared by its frames). When the prior is only a guess
// (focal_known = false), focal and k1/k2 are refined by global BA once enough images constrain them; the
// principal point, aspect and tangential distortion are held during growth; at the end each is freed only when
// the data ask for it and determine it (nested-model tests, self_calibration.h), reported in MapperResult; k1
// and k2 go back to the prior's values at the end unless the same tests say the data need them.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"
#include "fmv3d/sfm/focal_decision.h"
#include "fmv3d/sfm/guided_completion.h"
#include "fmv3d/sfm/self_calibration.h"
#include "fmv3d/sfm/track_builder.h"

namespace fmv3d::sfm {

struct MapperImage {
  uint32_t id = 0;
  uint32_t camera_id = 1;
  std::string name;
  std::vector<Eigen::Vector2d> keypoints;            // pixels, fmv3d convention
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;  // optional, same size as keypoints
  // Optional, one row per keypoint: the final polish completes tracks by projection with them
  // (guided_completion.h). Must outlive the mapper run.
  const features::Descriptors* descriptors = nullptr;
  // Optional, one per keypoint: SIFT scales, for the keypoint noise of that completion (guided_completion.h).
  std::vector<float> scales;
};

struct MapperCamera {
  core::Camera camera;       // prior intrinsics
  bool focal_known = false;  // false: the prior is a guess, self-calibrate
  // > 0: camera.f's relative 1σ, a soft prior in every bundle adjustment (BundleAdjustmentConfig::focal_priors).
  double focal_prior_sigma = 0;
};

struct MapperInput {
  std::map<uint32_t, MapperCamera> cameras;
  std::vector<MapperImage> images;
  std::vector<features::VerifiedPair> pairs;
  // The operator's tie points appended to the keypoints (features/manual_matches.h): image id → first such
  // index; their observations weigh manual_weight times an automatic one in every bundle adjustment.
  std::map<uint32_t, uint32_t> manual_from;
  double manual_weight = 1;
};

struct MapperOptions {
  // Initial pair.
  int init_min_inliers = 60;
  double init_min_tri_angle_deg = 4.0;  // median angle wanted; relaxed step by step when no pair has it
  double init_max_h_ratio = 0.85;       // H inliers / pair inliers above this: planar/rotation, tried last
  int init_max_candidates = 20;
  // Registration.
  double abs_pose_max_error_px = 12;
  int abs_pose_min_inliers = 15;
  double abs_pose_min_inlier_ratio = 0.2;
  int min_visible_points = 15;  // an image needs this many triangulated tracks to be tried
  int max_registration_trials = 4;
  // Before the final adjustment, re-register images whose pose a fresh absolute pose over all their 2D–3D
  // correspondences contradicts with twice the support (an early registration on ambiguous matches).
  bool relocalise = true;
  // Triangulation / filtering.
  double tri_min_angle_deg = 1.5;
  double tri_max_error_px = 4;
  bool tri_ignore_two_view_tracks = true;  // TriangulatorOptions::ignore_two_view_tracks
  // Before the final adjustment (and once more after it), each point's track gains the keypoints of co-visible
  // images inside the search region its projection's uncertainty and their keypoint noise set (at most
  // tri_max_error_px) whose descriptors look like the track's (guided_completion.h); needs
  // MapperImage::descriptors (and ::scales for the noise by keypoint size). The descriptor bound lets this share of
  // decoy searches (a keypoint there by chance) through. Off by default: checked against the true cameras, even
  // these additions are off by more than 1 px twice as often as the matcher's observations (fountain-P11 32% vs
  // 18%), and on a 36-frame 960x540 synthetic orbit of repetitive texture the centre error grows (0.013 → 0.022%).
  bool guided_completion = false;
  double guided_completion_false_accept_rate = 0.01;
  double guided_completion_ratio = 0.8;  // ratio test against a rival keypoint near the projection (1: off)
  bool guided_completion_prune = true;   // drop additions the following adjustment does not explain
  double filter_max_error_px = 4;
  double filter_min_angle_deg = 1.5;
  // Bundle adjustment.
  int local_ba_num_images = 6;
  // Iteration budgets, measured on a 40-frame 960x540 synthetic orbit (town, k1 = -0.08, focal guessed): the
  // final BA at 1e-9 took 120 iterations, at 1e-7 it stops after 28 with centre 0.0036%, rotation 0.032°,
  // focal 0.026%; local and intermediate global BAs only need to stay near the optimum for the next image.
  int local_ba_max_iterations = 10;
  // Global BA when the model grew by 50%. Local BAs keep a video model near its optimum between them: on a
  // 61-keyframe 960x540 clip and a 40-frame orbit, 1.5 instead of 1.1 (COLMAP's) gave the same final accuracy
  // at about half the global BA work (the final BA still converges the whole model).
  double global_ba_growth_ratio = 1.5;
  int global_ba_every_image_below = 12;  // ... and after every image while the model is small
  // Intermediate global BAs: near the optimum is enough. 5 instead of 10 left the final accuracy of the clip
  // and the orbit above unchanged (the final BA converges the whole model) at ~20% less global BA work.
  int global_ba_max_iterations = 5;
  int final_ba_max_iterations = 100;
  double final_ba_function_tolerance = 1e-7;
  int refine_focal_min_images = 3;
  int refine_k2_min_images = 6;
  // From this many images on, the final adjustment tests holding k2 and k1 at the prior, then freeing the
  // principal point (and a telephoto scan's focal), each by the nested-model test of self_calibration.h:
  // significant by BIC and determined by the BA's covariance (its squared shift exceeds its posterior variance).
  int refine_principal_point_min_images = 8;
  // A fixed Δχ² threshold instead of BIC's k·ln(n) (0). A threshold tuned on our own renders is no model selection:
  // 1000 held Herz-Jesus-P8's principal point (Δχ² 585, 17 px off: centre 0.041% of the extent, BIC 0.027%) and
  // a synthetic orbit's true k1 = −0.08 (Δχ² 972). A 24-frame synthetic orbit with a centred principal point
  // keeps it held under BIC (Δχ² 1.8 vs 23.4).
  double self_calibration_min_delta_chi2 = 0;
  // After the principal point, test freeing the aspect s_u (non-square pixels) by the same rule. Off by default:
  // on fountain-P11 the test frees it at fx/fy 1.0016 ± 0.0002 (COLMAP's free fx, fy: 1.0013) where the truth is
  // 0.9983, and every camera figure gets worse (focal vs fy 0.23 → 0.42%, rotation 0.074 → 0.080°). Cameras
  // orbiting at one roll see an fx/fy change almost as a vertical stretch of the scene (self_calibration_test.cc),
  // so a small systematic error decides it; rolled cameras determine it.
  bool self_calibrate_aspect = false;
  // The final model states the posterior σ of each free intrinsic (IntrinsicsPosterior); one whose 1σ moves the
  // image corner's projection by more than this (pixels) is reported as weakly determined.
  double weak_intrinsic_corner_px = 1.0;
  // Focal. A guessed prior is replaced by a scan over focal candidates on the strongest pairs (focal_scan.h).
  int focal_scan_pairs = 5;
  // A guessed focal that the first mapping's adjustments moved by more than this share from its start is taken as
  // the start of a second mapping (the first grew its early poses and points under the wrong focal); the second
  // is kept unless it registers fewer images. 0: never. Moves of 27–44% (a scan's lower bound on short orbits)
  // gave cameras 2–10× closer to the truth the second time; fountain-P11 and Herz-Jesus-P8 move 5.8% and map to
  // the same figures twice, so they are mapped once (bench/RESULTS.md, "Self-calibration").
  double focal_restart_min_change = 0.1;
  // The move is checked from this many images on, at the first mapping's intermediate global adjustments (the
  // first check and any that sees the move on a converged adjustment of a copy), and growth stops at the first that
  // shows it: the rest would be mapped again. The second mapping ends the same (40-frame orbit, 16 and 24-frame
  // orbits: identical cameras) at 42–58% of the mapping time. Smaller models are checked when finished.
  int focal_restart_min_images = 12;
  int focal_dolly_min_images = 15;       // telephoto: multi-view focal scan once the model has this many images
  double focal_dolly_max_factor = 64;    // ... over the two-view lower bound times 1 .. this (steps of √2)
  bool fix_known_focal = false;          // a trusted prior (calibration, telemetry, --focal) stays fixed in BA
  double narrow_field_max_radius = 0.1;  // half-diagonal / f below this: k1, k2 unobservable, held at the prior
  bool refine_tangential = false;
  double ba_loss_scale_px = 1.0;
  // Models.
  int min_model_size = 3;
  int max_models = 20;
  uint64_t seed = 42;
  void Check() const;
};

// Seconds spent per kind of work, summed over every model built.
struct MapperTimings {
  double init = 0, registration = 0, triangulation = 0, local_ba = 0, global_ba = 0, filtering = 0;
  double total = 0;  // the whole mapper run
};

// The largest model's tracks against those the verified matches allow (track_builder.h).
struct TrackSummary {
  size_t union_find_tracks = 0, union_find_links = 0, union_find_conflicts_cut = 0;
  double union_find_mean_length = 0, union_find_mean_length_3_or_more_views = 0;
  std::optional<TrackCoverage> largest_model;  // none when no model was built
};

// One pass of track completion by projection (guided_completion.h) and what the next adjustment removed of it.
struct GuidedCompletionPass {
  size_t observations_before = 0;
  GuidedCompletionOptions options;
  GuidedCompletionStats stats;  // without the list of additions
  double seconds = 0;
  std::optional<size_t> removed_after_adjustment;  // set when the additions were pruned
};

struct MapperStats {
  size_t correspondences = 0, invalid_matches_skipped = 0, models = 0;
  int relocalised_images = 0;
  TrackSummary tracks;
  std::vector<GuidedCompletionPass> guided_completion;  // the largest model's passes; empty when not run
  MapperTimings seconds;
};

struct MapperResult {
  std::vector<core::Reconstruction> models;                            // largest first
  std::vector<std::vector<NestedModelTestResult>> self_calibration;    // per model: the final tests, in order
  std::vector<std::vector<IntrinsicsPosterior>> intrinsics_posterior;  // per model: each camera's, final model
  std::vector<FocalDecision> focal_decision;                           // per model: how its focal was decided
  std::map<uint32_t, std::string> left_out;  // image id → reason it is not in the largest model
  MapperStats stats;                         // counts and timings per stage
};

// Never throws on bad data (too few matches, unrelated images): such images are left out with a reason.
// Throws fmv3d::Error only for invalid options or inconsistent input (image referring to an unknown camera).
MapperResult RunIncrementalMapper(const MapperInput& input, const MapperOptions& options);

}  // namespace fmv3d::sfm
