// `fmv3d match WS`: pair selection, descriptor matching and geometric verification → WS/matches/; then the
// operator's tie points (WS/manual/tiepoints.json or --tiepoints) as correspondences verification never discards.
#include <spdlog/spdlog.h>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/match_stage.h"

namespace fmv3d::app::cmd_match {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("match", "Match features between image pairs and verify them (WS/matches/)");
  struct Args {
    std::string ws, pairs = "auto", matcher = "auto";
    features::MatchStageOptions opt;
    bool no_mutual = false, no_quadratic = false, no_tiepoints = false, force = false;
    std::string tiepoints;
    uint64_t seed = 0;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (with frames/ and features/)")->required();
  cmd->add_option("--pairs", a->pairs,
                  "auto | exhaustive | sequential | spatial (auto: exhaustive up to 50 images, "
                  "then spatial for photos that all carry GPS, else sequential; spatial: overlapping ground footprints "
                  "from the frames' telemetry)")
      ->capture_default_str();
  cmd->add_option("--spatial-overlap", a->opt.pairs.spatial_overlap_factor,
                  "spatial: pair frames whose footprint centres are closer than this times the radii sum")
      ->capture_default_str();
  cmd->add_option("--spatial-neighbours", a->opt.pairs.spatial_max_neighbours,
                  "spatial: nearest overlapping frames kept per frame")
      ->capture_default_str();
  cmd->add_option("--overlap", a->opt.pairs.overlap, "sequential: match each frame with the next N")
      ->capture_default_str();
  cmd->add_flag("--no-quadratic", a->no_quadratic, "sequential: no extra pairs at frame distances 2^k");
  cmd->add_option("--loop-closure", a->opt.pairs.loop_closure_candidates,
                  "sequential: most similar distant frames per frame by a global descriptor (0 = off)")
      ->capture_default_str();
  cmd->add_option("--matcher", a->matcher, "auto | flann | bruteforce")->capture_default_str();
  cmd->add_option("--ratio", a->opt.match.ratio, "Lowe ratio")->capture_default_str();
  cmd->add_flag("--no-mutual", a->no_mutual, "Skip the mutual (cross) check");
  cmd->add_option("--flann-checks", a->opt.match.flann_checks, "kd-tree leaves visited per query")
      ->capture_default_str();
  cmd->add_option("--max-error", a->opt.verify.max_error_px,
                  "RANSAC inlier threshold in pixels (0 = auto: max(1.5, image size / 2000))")
      ->capture_default_str();
  cmd->add_option("--min-inliers", a->opt.verify.min_inliers, "Pairs with fewer inliers are dropped")
      ->capture_default_str();
  cmd->add_option("--max-memory", a->opt.max_memory_mb,
                  "MB for the descriptors of the images being matched; beyond it the least recently used image is "
                  "dropped and read again when needed")
      ->capture_default_str();
  cmd->add_option("--seed", a->seed, "Random seed (results are deterministic for a seed)")->capture_default_str();
  cmd->add_option("--tiepoints", a->tiepoints,
                  "The operator's tie points (docs/manual-inputs.md) instead of WS/manual/tiepoints.json");
  cmd->add_flag("--no-tiepoints", a->no_tiepoints, "Ignore WS/manual/tiepoints.json");
  cmd->add_flag("--force", a->force,
                "Match every pair again, even those whose features, cameras and options are unchanged since the "
                "last run (WS/matches/automatic.*)");
  cmd->add_option("--tie-max-epipolar-px", a->opt.manual.max_epipolar_px,
                  "Report tie points farther than this from the automatic epipolar line (they are kept)")
      ->capture_default_str();
  cmd->add_option("--tie-scale", a->opt.manual.keypoint_scale_px, "Descriptor scale at a clicked point, pixels")
      ->capture_default_str();
  cmd->callback([a] {
    const core::Workspace ws(a->ws);
    if (!a->tiepoints.empty()) a->opt.tiepoints_file = a->tiepoints;
    a->opt.use_tiepoints = !a->no_tiepoints;
    a->opt.reuse = !a->force;
    ws.Require(ws.frames_json(), "frames");
    ws.Require(ws.features_dir(), "features");
    auto& o = a->opt;
    o.pairs.mode = features::ParsePairMode(a->pairs);
    o.pairs.quadratic = !a->no_quadratic;
    o.match.mutual = !a->no_mutual;
    if (a->matcher == "auto")
      o.match.type = features::MatcherType::kAuto;
    else if (a->matcher == "flann")
      o.match.type = features::MatcherType::kFlann;
    else if (a->matcher == "bruteforce")
      o.match.type = features::MatcherType::kBruteForce;
    else
      throw Error("match: unknown --matcher '" + a->matcher + "' (auto, flann, bruteforce)");
    o.pairs.seed = o.match.seed = o.verify.seed = a->seed;
    features::RunMatchStage(ws.root(), o);
  });
}

const RegisterCommand reg(300, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_match
