// `fmv3d mesh WS`: screened Poisson surface from WS/dense/fused.ply → WS/mesh/poisson.ply, report/mesh.json.
#include <map>
#include <string>

#include "command.h"
#include "fmv3d/surface/mesh_stage.h"

namespace fmv3d::app::cmd_mesh {
namespace {

void Add(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("mesh", "Poisson surface from the dense cloud (WS/mesh/poisson.ply, report/mesh.json)");
  struct Args {
    std::string ws;
    surface::MeshStageOptions opt;
  };
  auto a = std::make_shared<Args>();
  auto& p = a->opt.poisson;
  cmd->add_option("WS", a->ws, "Workspace folder (with dense/fused.ply)")->required();
  cmd->add_option("--depth", p.depth, "Octree depth (0: from the point spacing)")->capture_default_str();
  cmd->add_option("--cell-spacing", p.cell_to_spacing, "Automatic depth: finest cell width in median point spacings")
      ->capture_default_str();
  cmd->add_option("--max-depth", p.max_depth, "Upper bound of the automatic depth")->capture_default_str();
  cmd->add_option("--trim", p.density_quantile, "Share of lowest-density vertices removed (0..0.9)")
      ->capture_default_str();
  cmd->add_option("--max-distance", p.max_point_distance,
                  "Remove vertices farther than this many point spacings from every point (0: off)")
      ->capture_default_str();
  cmd->add_option("--surface", p.kind,
                  "open (default): trimmed to the points (terrain, towns) | watertight: closed (objects)")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, surface::SurfaceKind>{{"open", surface::SurfaceKind::kOpen},
                                                      {"watertight", surface::SurfaceKind::kWatertight}},
          CLI::ignore_case));
  cmd->add_option("--min-support", p.components.min_support_points,
                  "Keep connected pieces with at least this many dense points on them")
      ->capture_default_str();
  cmd->add_option("--min-area", p.components.min_area_cells,
                  "Keep connected pieces of at least this area, in octree cells squared")
      ->capture_default_str();
  cmd->add_option("--crop-margin", p.crop_margin, "Crop box enlargement, fraction of the points' diagonal")
      ->capture_default_str();
  cmd->add_option("--max-memory", p.max_memory_mb,
                  "MB for Poisson's octree and the point arrays: the points are averaged in finer cells, then the "
                  "depth lowered, until the estimate fits "
                  "(report/mesh.json \"memory\"; 0: no limit)")
      ->capture_default_str();
  cmd->add_option("--faces", p.target_faces, "Decimate to about this many faces (0: keep all)")->capture_default_str();
  cmd->add_flag("!--no-normal-estimation", a->opt.estimate_missing_normals,
                "Fail on a cloud without normals instead of estimating them");
  cmd->callback([a] {
    a->opt.poisson.threads = Globals().threads;
    surface::RunMeshStage(a->ws, a->opt);
  });
}

const RegisterCommand reg(600, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_mesh
