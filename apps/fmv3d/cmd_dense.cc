// `fmv3d dense WS`: PatchMatch depth/normal maps per registered frame + fusion → WS/dense/fused.ply,
// WS/dense/maps/, WS/report/dense.json.
#include "command.h"
#include "fmv3d/mvs/dense_stage.h"

namespace fmv3d::app::cmd_dense {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("dense", "Dense multi-view stereo on CPU (WS/dense/fused.ply, report/dense.json)");
  struct Args {
    std::string ws;
    mvs::DenseStageOptions opt;
    bool no_geometric = false, no_previews = false, no_coarse = false, no_visibility = false;
  };
  auto a = std::make_shared<Args>();
  auto& o = a->opt;
  cmd->add_option("WS", a->ws, "Workspace folder (with sparse/ and frames/)")->required();
  cmd->add_option("--max-size", o.max_size, "Working resolution: longer image side in pixels (0 = full size)")
      ->capture_default_str();
  cmd->add_option("--max-sources", o.max_sources, "Source views per reference view (1-16)")->capture_default_str();
  cmd->add_option("--reference-coverage", o.references.coverage,
                  "Depth maps only for the fewest views that see every sparse point this many times; the others "
                  "are stereo sources only (for redundant captures such as video; 0 = a map for every view)")
      ->capture_default_str();
  cmd->add_option("--reference-demand", o.references.demand_fraction,
                  "Reference cover: stop when this fraction of the coverage demand is met")
      ->capture_default_str();
  cmd->add_option("--iterations", o.patch_match.iterations, "PatchMatch rounds (photometric pass)")
      ->capture_default_str();
  cmd->add_option("--fine-iterations", o.patch_match.fine_iterations,
                  "PatchMatch rounds at full resolution after the half-resolution pass")
      ->capture_default_str();
  cmd->add_option("--geom-iterations", o.patch_match.geom_iterations, "PatchMatch rounds of the geometric pass")
      ->capture_default_str();
  cmd->add_option("--window-radius", o.patch_match.window_radius, "NCC patch half-size, pixels")->capture_default_str();
  cmd->add_option("--window-step", o.patch_match.window_step, "NCC patch sampling step, pixels")->capture_default_str();
  cmd->add_option("--max-cost", o.patch_match.max_cost, "Drop pixels whose 1-NCC stays above this (0-2]")
      ->capture_default_str();
  cmd->add_option("--min-views", o.fusion.min_views, "Consistent views per fused point (reference included)")
      ->capture_default_str();
  cmd->add_option("--max-depth-error", o.fusion.max_depth_error, "Fusion: relative depth agreement")
      ->capture_default_str();
  cmd->add_option("--max-reproj-error", o.fusion.max_reproj_error_px,
                  "Fusion: forward-backward reprojection agreement, pixels")
      ->capture_default_str();
  cmd->add_option("--max-normal-error", o.fusion.max_normal_error_deg, "Fusion: normal agreement, degrees")
      ->capture_default_str();
  cmd->add_option("--edge-erosion", o.fusion.edge_erosion_px,
                  "Fusion: drop pixels this close to an occluding depth edge, foreground side (0: off)")
      ->capture_default_str();
  cmd->add_option("--edge-jump", o.fusion.edge_depth_jump, "Fusion: relative depth step of an occluding edge")
      ->capture_default_str();
  cmd->add_option("--sparse-tolerance", o.fusion.sparse_tolerance,
                  "Fusion: drop a map's pieces whose depth the view's own sparse points contradict, beyond this "
                  "relative depth (periodic texture matched one period off; 0: off)")
      ->capture_default_str();
  cmd->add_option("--max-uncertainty", o.fusion.max_relative_uncertainty,
                  "Fusion: drop points whose expected error along the normal (from their consistent views' "
                  "distance, grazing angle, spread of directions and image texture) exceeds this multiple of the "
                  "cloud's median (0: off)")
      ->capture_default_str();
  cmd->add_option("--seed", o.patch_match.seed, "Random seed")->capture_default_str();
  cmd->add_option("--max-memory", o.max_memory_mb,
                  "MB for the views held at once (the undistorted-view cache and fusion's window of depth maps); "
                  "beyond it fusion drops the least recently used map and reads it again when needed")
      ->capture_default_str();
  cmd->add_flag("--no-geometric", a->no_geometric, "Skip the geometric-consistency pass (faster, noisier)");
  cmd->add_flag("--no-coarse", a->no_coarse, "No half-resolution first pass");
  cmd->add_flag("--no-visibility-filter", a->no_visibility, "Keep points that other views see through");
  cmd->add_flag("--no-previews", a->no_previews, "Do not write PNG previews of the maps");
  cmd->add_flag("--fuse-only", o.fuse_only, "Only fuse the maps already in WS/dense/maps (other fusion options)");
  cmd->add_flag("--keep-photometric", o.keep_photometric, "Keep the photometric-pass maps");
  cmd->callback([a] {
    a->opt.geometric = !a->no_geometric;
    a->opt.previews = !a->no_previews;
    a->opt.patch_match.coarse_to_fine = !a->no_coarse;
    a->opt.fusion.visibility_filter = !a->no_visibility;
    mvs::RunDenseStage(a->ws, a->opt);
  });
}

const RegisterCommand reg(500, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_dense
