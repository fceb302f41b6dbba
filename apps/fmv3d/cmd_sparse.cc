// `fmv3d sparse WS`: incremental structure-from-motion + bundle adjustment → WS/sparse/, WS/report/sparse.json.
#include <spdlog/spdlog.h>

#include "command.h"
#include "fmv3d/sfm/sparse_stage.h"

namespace fmv3d::app::cmd_sparse {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("sparse", "Incremental SfM + bundle adjustment (WS/sparse/, report/sparse.json)");
  struct Args {
    std::string ws;
    sfm::SparseStageOptions opt;
    bool no_tiepoints = false;
  };
  auto a = std::make_shared<Args>();
  auto& m = a->opt.mapper;
  cmd->add_option("WS", a->ws, "Workspace folder (with frames/, features/, matches/)")->required();
  cmd->add_option("--init-min-inliers", m.init_min_inliers, "Initial pair: minimum verified matches")
      ->capture_default_str();
  cmd->add_option("--init-min-angle", m.init_min_tri_angle_deg,
                  "Initial pair: median triangulation angle wanted, degrees (relaxed when no pair has it)")
      ->capture_default_str();
  cmd->add_option("--max-error", m.abs_pose_max_error_px, "Absolute pose RANSAC threshold, pixels")
      ->capture_default_str();
  cmd->add_option("--min-angle", m.tri_min_angle_deg, "Minimum triangulation angle, degrees")->capture_default_str();
  cmd->add_option("--filter-angle", m.filter_min_angle_deg, "Points below this angle are removed, degrees")
      ->capture_default_str();
  cmd->add_option("--tri-max-error", m.tri_max_error_px, "Triangulation / filter reprojection error, pixels")
      ->capture_default_str();
  cmd->add_option("--pp-min-images", m.refine_principal_point_min_images,
                  "Test freeing the principal point from this model size on")
      ->capture_default_str();
  cmd->add_option("--self-cal-delta-chi2", m.self_calibration_min_delta_chi2,
                  "Self-calibration tests: fixed chi-square gain needed to free a parameter (0: BIC's k ln n)")
      ->capture_default_str();
  cmd->add_option("--focal-restart", m.focal_restart_min_change,
                  "A guessed focal that mapping moves by more than this share maps the images again from the refined "
                  "focal (0: never)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10.0));
  cmd->add_flag("--self-cal-aspect", m.self_calibrate_aspect,
                "Also test freeing the pixel aspect (fx/fy) by the nested-model test, after the principal point");
  cmd->add_flag("!--keep-two-view-tracks", m.tri_ignore_two_view_tracks,
                "Also triangulate matches seen in two images only (no third image can observe them)");
  cmd->add_flag("--guided-completion", m.guided_completion,
                "Complete the tracks by projection (keypoints near a point's projection whose descriptors look like "
                "its track's) around the final adjustment");
  cmd->add_option("--guided-false-accept", m.guided_completion_false_accept_rate,
                  "Guided completion: share of decoy searches (a keypoint there by chance) the descriptor bound lets "
                  "through")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_option("--guided-ratio", m.guided_completion_ratio,
                  "Guided completion: ratio test against a rival keypoint near the projection (1: none)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_flag("!--no-guided-prune", m.guided_completion_prune,
                "Guided completion: keep the additions the following adjustment does not explain");
  cmd->add_flag("--tangential", m.refine_tangential, "Also refine p1, p2");
  cmd->add_option("--local-ba-iterations", m.local_ba_max_iterations, "Local BA: maximum iterations")
      ->capture_default_str();
  cmd->add_option("--global-ba-iterations", m.global_ba_max_iterations, "Intermediate global BA: maximum iterations")
      ->capture_default_str();
  cmd->add_option("--global-ba-ratio", m.global_ba_growth_ratio,
                  "Global BA whenever the model has grown by this factor")
      ->capture_default_str();
  cmd->add_option("--final-ba-iterations", m.final_ba_max_iterations, "Final global BA: maximum iterations")
      ->capture_default_str();
  cmd->add_option("--final-ba-tolerance", m.final_ba_function_tolerance,
                  "Final global BA: relative cost decrease at which it stops")
      ->capture_default_str();
  cmd->add_option("--max-models", m.max_models, "Maximum number of disconnected models")->capture_default_str();
  cmd->add_option("--focal", a->opt.focal_px, "Focal prior in pixels for every camera (overrides frames.json)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--hfov", a->opt.hfov_deg, "Focal prior from the horizontal field of view, degrees")
      ->check(CLI::Range(0.0, 180.0));
  cmd->add_flag("--fix-focal", m.fix_known_focal,
                "Keep a known focal (calibration, sensor database, EXIF, --focal/--hfov) fixed in BA");
  cmd->add_option("--max-memory", a->opt.max_memory_mb,
                  "Memory budget, MB: when the model's bound exceeds it, part of each image's matched keypoints "
                  "(the least connected, spread over the image) is left out of mapping until it fits (bundle "
                  "adjustment holds every observation)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--focal-scan-pairs", m.focal_scan_pairs, "Guessed focal: pairs the focal scan uses")
      ->capture_default_str();
  cmd->add_option("--seed", m.seed, "Random seed")->capture_default_str();
  cmd->add_option("--tie-weight", a->opt.manual.options.weight,
                  "Weight of a tie-point observation against an automatic one in bundle adjustment")
      ->capture_default_str();
  cmd->add_option("--tie-min-points", a->opt.manual.options.min_tie_points,
                  "Tie points (already in the model) a left-out frame needs to register through them")
      ->capture_default_str();
  cmd->add_flag("--no-tiepoints", a->no_tiepoints, "Ignore the tie points of WS/matches/manual.json");
  cmd->callback([a] {
    a->opt.mapper.filter_max_error_px = a->opt.mapper.tri_max_error_px;
    a->opt.manual.enabled = !a->no_tiepoints;
    sfm::RunSparseStage(a->ws, a->opt);
  });
}

const RegisterCommand reg(400, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_sparse
