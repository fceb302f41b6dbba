// `fmv3d tiles WS`: OGC 3D Tiles (point octree + textured mesh) for the console (pipeline/tiles_stage.h).
#include <cstdio>
#include <memory>

#include "command.h"
#include "fmv3d/pipeline/tiles_stage.h"

namespace fmv3d::app::cmd_tiles {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("tiles", "Write 3D Tiles (tiles/tileset.json) of the dense cloud and textured mesh");
  auto ws = std::make_shared<std::string>();
  auto o = std::make_shared<pipeline::TilesOptions>();
  cmd->add_option("WS", *ws, "Workspace folder")->required();
  cmd->add_option("--tile-points", o->octree.max_points_per_tile, "Points per tile at most")->capture_default_str();
  cmd->add_option("--max-depth", o->octree.max_depth, "Octree levels below the root at most")->capture_default_str();
  cmd->callback([ws, o] {
    const auto s = pipeline::RunTilesStage(*ws, *o);
    std::printf("%s/tiles/tileset.json: %zu points in %zu tiles\n", ws->c_str(), s["points"].get<size_t>(),
                s["tiles"].get<size_t>());
  });
}

const RegisterCommand reg(760, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_tiles
