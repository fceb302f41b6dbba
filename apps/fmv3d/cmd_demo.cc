// `fmv3d demo`: for now, renders the default synthetic flight (building scene, orbit, 48 frames, 960x540,
// H.264 mp4) with its ground truth and says where the files are. The full pipeline will extend it.
#include <iostream>

#include "command.h"
#include "fmv3d/synth/synth.h"

namespace fmv3d::app {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "Render the default synthetic flight (later: run the whole pipeline)");
  auto out = std::make_shared<std::string>("demo");
  cmd->add_option("-o,--output", *out, "Output folder")->capture_default_str();
  cmd->callback([out] {
    synth::SynthOptions o;
    o.scene = "building";
    o.flight.path = "orbit";
    o.flight.frames = 48;
    o.width = 960;
    o.height = 540;
    o.format = "mp4";
    o.render.noise_sigma = 1.5;
    o.output = *out;
    const auto r = synth::RunSynth(o);
    std::cout << "demo: synthetic flight of " << r.frames << " frames\n"
              << "  video:        " << (o.output / "flight.mp4").string() << "\n"
              << "  ground truth: " << (o.output / "truth").string() << " (COLMAP text model), "
              << (o.output / "truth.json").string() << "\n"
              << "  scene mesh:   " << (o.output / "scene.obj").string() << "\n";
  });
}

const RegisterCommand reg(1000, Add);

}  // namespace
}  // namespace fmv3d::app
