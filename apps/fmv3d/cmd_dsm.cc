// `fmv3d dsm WS [--gsd M]`: DSM GeoTIFF (UTM, highest surface per cell), hillshade PNG and LAS 1.4 points of a
// georeferenced workspace → WS/geo/{dsm.tif, hillshade.png, points.las, dsm.json}.
#include <cstdio>

#include "command.h"
#include "fmv3d/geo/dsm.h"

namespace fmv3d::app::cmd_dsm {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("dsm", "DSM GeoTIFF, hillshade and LAS of a georeferenced workspace (WS/geo/)");
  struct Args {
    std::string ws;
    double gsd = 0;
    bool no_las = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (after `fmv3d georef`)")->required();
  auto* gsd =
      cmd->add_option("--gsd", a->gsd, "Cell size, metres (default: from the data)")->check(CLI::PositiveNumber);
  cmd->add_flag("--no-las", a->no_las, "Do not write geo/points.las");
  cmd->callback([a, gsd] {
    geo::DsmOptions o;
    if (gsd->count()) o.gsd = a->gsd;
    o.write_las = !a->no_las;
    const auto j = geo::RunDsmStage(a->ws, o);
    std::printf("dsm: %dx%d cells of %.3f m (%s), %zu with data, heights %.2f..%.2f m -> %s/geo/dsm.tif\n",
                j["width"].get<int>(), j["height"].get<int>(), j["gsd_m"].get<double>(),
                j["crs"].get<std::string>().c_str(), j["valid_cells"].get<size_t>(),
                j["height_range_m"][0].get<double>(), j["height_range_m"][1].get<double>(), a->ws.c_str());
  });
}

const RegisterCommand reg(710, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_dsm
