// `fmv3d ortho WS`: orthophoto GeoTIFF on the DSM's grid (WS/geo/ortho.tif) from WS/mesh/textured.obj seen
// from straight above, or the coloured points when there is no textured mesh.
#include <cstdio>

#include "command.h"
#include "fmv3d/geo/dsm.h"

namespace fmv3d::app::cmd_ortho {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("ortho", "Orthophoto GeoTIFF on the DSM grid (WS/geo/ortho.tif)");
  auto ws = std::make_shared<std::string>();
  cmd->add_option("WS", *ws, "Workspace folder (after `fmv3d dsm`)")->required();
  cmd->callback([ws] {
    const auto j = geo::RunOrthoStage(*ws);
    std::printf("ortho: %dx%d cells of %.3f m, %d seen, from %s -> %s/geo/ortho.tif\n", j["width"].get<int>(),
                j["height"].get<int>(), j["gsd_m"].get<double>(), j["valid_cells"].get<int>(),
                j["source"].get<std::string>().c_str(), ws->c_str());
  });
}

const RegisterCommand reg(720, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_ortho
