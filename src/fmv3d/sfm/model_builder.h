// The mapper's model builder, internal to sfm/: grows one model from an initial pair (incremental_mapper.h runs
// it once per disconnected model). Its parts live in separate units:
//   mapper_initial_pair.cc   focal choice and the initial pair (initial_pair.h evaluates a candidate)
//   model_builder.cc         registration, relocalisation of wrong poses, local/global adjustment, the loop policy
//   mapper_calibration.cc    the final self-calibration tests and the dolly-zoom focal scan
// The primitives it calls (register, triangulate, filter) are mapper_primitives.h and triangulator.h.
#pragma once

#include <chrono>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/correspondence_graph.h"
#include "fmv3d/sfm/focal_decision.h"
#include "fmv3d/sfm/guided_completion.h"
#include "fmv3d/sfm/incremental_mapper.h"
#include "fmv3d/sfm/initial_pair.h"
#include "fmv3d/sfm/mapper_primitives.h"
#include "fmv3d/sfm/self_calibration.h"
#include "fmv3d/sfm/triangulator.h"

namespace fmv3d::sfm::mapper {

constexpr double kDeg = M_PI / 180.0;
using Clock = std::chrono::steady_clock;

inline double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

// Seconds spent per part of the mapper, summed over every model.
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

// One step of the growth loop (the loop policy's status).
enum class GrowthStep {
  kRegistered,   // an image was registered (and triangulated, locally adjusted)
  kNoCandidate,  // no image left that sees enough of the model or deserves another trial
  kAllFailed,    // every candidate was tried and failed
};

class ModelBuilder {
 public:
  ModelBuilder(const MapperInput& input, const std::map<uint32_t, const MapperImage*>& images,
               const CorrespondenceGraph& graph, const MapperOptions& options, const std::set<uint32_t>& pool,
               MapperTimings* timings)
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

  // Starts these cameras at the given focal (camera id → px) instead of scanning for one, the focal free from the
  // start: a second mapping from the focal an earlier one refined to (incremental_mapper.cc).
  void StartFocalAt(std::map<uint32_t, double> focal_px) { focal_start_ = std::move(focal_px); }
  // Stops growth at an intermediate global adjustment once a guessed focal (the scans' start) has moved by more
  // than min_change from where growth started it, with at least min_images registered: the images are then mapped
  // again from the refined focal (incremental_mapper.cc), so growing on under the wrong one would be wasted.
  void StopWhenFocalMoves(double min_change, int min_images) {
    stop_focal_change_ = min_change;
    stop_focal_min_images_ = min_images;
  }
  // Set when growth stopped that way: the moved cameras' focal (camera id → px) and the largest move.
  struct FocalStop {
    std::map<uint32_t, double> focal_px;
    double start_px = 0, final_px = 0, change = 0;  // the camera that moved most
  };
  const std::optional<FocalStop>& focal_stop() const { return focal_stop_; }
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
  // The final model's posterior uncertainty of each camera's free intrinsics (self_calibration.h).
  const std::vector<IntrinsicsPosterior>& intrinsics_posterior() const { return posterior_; }
  // How the focal was decided (stated, or the two-view and dolly-zoom scans), for report/sparse.json.
  const FocalDecision& focal_decision() const { return focal_decision_; }
  // The final polish's track completion by projection (guided_completion.h), for report/sparse.json.
  const std::vector<GuidedCompletionPass>& guided_completion() const { return guided_completion_; }

 private:
  // Initialisation (mapper_initial_pair.cc).
  void ChooseFocal(const std::vector<InitialPairCandidate>& cands);
  bool TryInitialPair(const InitialPairCandidate& c);
  // The prior camera with the scan's lens distortion (the focal scale is applied by the initial pair's code).
  core::Camera InitialCamera(uint32_t camera_id) const;
  // Growth (model_builder.cc).
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
    for (const auto& [id, mc] : input_.cameras)
      if (mc.focal_known && mc.focal_prior_sigma > 0)
        cfg.focal_priors[id] = {mc.camera.f, mc.focal_prior_sigma * mc.camera.f};
    return cfg;
  }
  // Images sitting at a wrong pose moved to one that explains clearly more correspondences; returns how many.
  int ReRegisterWrongPoses();
  // Completes the tracks by projection into co-visible images (guided_completion.h) when descriptors are given;
  // returns the observations added (each pass is reported).
  size_t CompleteTracksByProjection();
  // After the adjustment that followed a completion: removes the additions it does not explain
  // (RemoveAdditionsThatDoNotFit); returns how many.
  size_t PruneGuidedAdditions();
  KeypointScales Scales() const;  // the registered images' keypoint scales, where known
  void LocalBundleAdjust(uint32_t image_id);
  BundleAdjustmentSummary GlobalBundleAdjust(bool final_pass);
  // The configuration and options of a global adjustment (intermediate, or converged for the final pass).
  void GlobalBaSetup(bool final_pass, BundleAdjustmentConfig* cfg, BundleAdjustmentOptions* o) const;
  // The guessed cameras' focal where growth starts refining it (after the scans), for StopWhenFocalMoves.
  void RecordGrowthFocal();
  // The largest move of a guessed focal in `rec` since RecordGrowthFocal; *stop describes it.
  double FocalMove(const core::Reconstruction& rec, FocalStop* stop) const;
  // After an intermediate global adjustment: whether growth stops for StopWhenFocalMoves (sets focal_stop_).
  bool StopForFocal();
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
  // Calibration (mapper_calibration.cc). The telephoto dolly-zoom focal scan (dolly_zoom_scan.h).
  void DollyZoomFocalScan();
  // The final nested-model test of one intrinsic group (self_calibration.h); true when it was freed.
  bool TrySelfCalibration(IntrinsicGroup group);
  // The final tests of the radial terms refined through growth, against the prior's values (k2, then k1 when k2
  // is not needed); true when the model changed.
  bool TryRadialSelfCalibration();
  // One radial term's test; *held is set when it goes back to the prior. True when the model changed.
  bool TestRadialTerm(IntrinsicGroup group, bool* held);
  // One nested-model test on *rec (rec_ or a copy), recorded in self_calibration_.
  bool RunSelfCalibrationTest(IntrinsicGroup group, core::Reconstruction* rec);
  // The final model's intrinsics posterior (posterior_), logged with a warning for each weakly determined one.
  void DescribeIntrinsicsPosterior();
  BundleAdjustmentOptions BaOptions() const;

  const MapperInput& input_;
  const std::map<uint32_t, const MapperImage*>& images_;
  const CorrespondenceGraph& graph_;
  double init_focal_scale_ = 1;
  std::optional<std::pair<double, double>> init_distortion_;  // k1, k2 of a wide lens found by the focal scan
  FocalDecision focal_decision_;
  std::map<uint32_t, double> focal_start_;  // StartFocalAt
  double stop_focal_change_ = 0;            // StopWhenFocalMoves (0: off)
  int stop_focal_min_images_ = 0;
  std::map<uint32_t, double> growth_focal_;  // RecordGrowthFocal
  std::optional<FocalStop> focal_stop_;
  bool focal_stop_checked_ = false;                      // the first check (a converged adjustment) was made
  std::vector<GuidedCompletionPass> guided_completion_;  // one entry per pass
  std::vector<std::pair<uint64_t, core::TrackElement>> guided_added_;  // the last completion's additions
  // Focal held through growth: a trusted prior the user wants kept, or a telephoto scan's lower bound (then
  // tested once at the end). Narrow field: distortion is unobservable and stays fixed.
  bool focal_fixed_ = false, focal_from_plateau_ = false, narrow_field_ = false, dolly_done_ = false;
  const MapperOptions& opt_;
  std::set<uint32_t> pool_;
  int num_relocalised_ = 0;
  MapperTimings* t_;
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
  std::vector<IntrinsicsPosterior> posterior_;
};

}  // namespace fmv3d::sfm::mapper
