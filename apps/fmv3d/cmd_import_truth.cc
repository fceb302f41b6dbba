// `fmv3d import-truth FORMAT PATH -o DIR`: converts benchmark ground-truth cameras (Strecha .camera folders,
// Middlebury *_par.txt, KWIVER .krtd folders) to a COLMAP text model, the form `evaluate-sparse --truth` reads.
#include <spdlog/spdlog.h>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/ground_truth.h"

namespace fmv3d::app::cmd_import_truth {
namespace {

struct Options {
  std::string format, path, out;
  int width = 0, height = 0, index_offset = 1;
};

void Add(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("import-truth", "Convert benchmark ground-truth cameras to a COLMAP text model");
  cmd->add_option("FORMAT", opt->format, "strecha | middlebury | krtd")
      ->required()
      ->check(CLI::IsMember({"strecha", "middlebury", "krtd"}));
  cmd->add_option("PATH", opt->path, "Folder of .camera/.krtd files, or a Middlebury *_par.txt")->required();
  cmd->add_option("-o,--output", opt->out, "Output folder for cameras.txt, images.txt, points3D.txt")->required();
  cmd->add_option("--size", opt->width, "krtd: image width")->check(CLI::PositiveNumber);
  cmd->add_option("--height", opt->height, "krtd: image height")->check(CLI::PositiveNumber);
  cmd->add_option("--index-offset", opt->index_offset, "krtd: KWIVER frame number of our frame 0")
      ->capture_default_str();
  cmd->callback([opt] {
    core::Reconstruction rec;
    if (opt->format == "strecha") {
      rec = io::ReadStrechaCameras(opt->path);
    } else if (opt->format == "middlebury") {
      rec = io::ReadMiddleburyPar(opt->path);
    } else {
      if (opt->width <= 0 || opt->height <= 0) throw Error("krtd needs the image size: --size W --height H");
      rec = io::ReadKrtdFolder(opt->path, opt->width, opt->height, opt->index_offset);
    }
    io::WriteColmapText(rec, opt->out);
    spdlog::info("{} cameras, {} images written to {}", rec.cameras.size(), rec.images.size(), opt->out);
  });
}

const RegisterCommand reg(950, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_import_truth
