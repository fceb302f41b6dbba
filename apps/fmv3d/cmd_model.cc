// `fmv3d model-info DIR`: summary of a COLMAP text model (ours or COLMAP's), a quick check of any sparse/ folder.
#include <spdlog/spdlog.h>

#include <iostream>

#include "command.h"
#include "fmv3d/io/colmap_model.h"

namespace fmv3d::app::cmd_model {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("model-info", "Summarise a COLMAP text model (cameras, images, points)");
  auto dir = std::make_shared<std::string>();
  cmd->add_option("DIR", *dir, "Folder with cameras.txt, images.txt, points3D.txt")->required();
  cmd->callback([dir] {
    const auto rec = io::ReadColmapText(*dir);
    std::cout << "cameras: " << rec.cameras.size() << "\nimages: " << rec.images.size()
              << "\npoints: " << rec.points.size() << "\nmean track length: " << rec.MeanTrackLength()
              << "\nmean reprojection error: " << rec.MeanReprojectionError() << " px\n";
    for (const auto& [id, c] : rec.cameras)
      std::cout << "camera " << id << ": " << c.width << "x" << c.height << " f=" << c.f << " aspect=" << c.aspect
                << " pp=(" << c.u0 << ", " << c.v0 << ") k1=" << c.k1 << " k2=" << c.k2 << " p1=" << c.p1
                << " p2=" << c.p2 << "\n";
  });
}

const RegisterCommand reg(900, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_model
