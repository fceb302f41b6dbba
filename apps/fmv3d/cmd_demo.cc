// `fmv3d demo`: render a synthetic flight around the CAD building, reconstruct it, measure it against the
// truth (pipeline/demo.h). The README's first command.
#include <cstdio>
#include <filesystem>
#include <memory>

#include "command.h"
#include "fmv3d/pipeline/demo.h"
#include "fmv3d/server/server.h"

namespace fmv3d::app::cmd_demo {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "Render a synthetic flight, reconstruct it and print its accuracy");
  auto o = std::make_shared<pipeline::DemoOptions>();
  auto out = std::make_shared<std::string>("demo");
  cmd->add_option("-o,--output", *out, "Output folder (re-running resumes)")->capture_default_str();
  cmd->add_option("--frames", o->frames, "Frames in the flight")->capture_default_str();
  cmd->add_option("--seed", o->seed, "Flight jitter and sensor noise seed")->capture_default_str();
  cmd->add_option("--max-features", o->max_features, "SIFT features per frame (more: better cameras, slower)")
      ->capture_default_str();
  cmd->callback([o, out] {
    o->output = *out;
    pipeline::RunDemo(*o);
    // The console opens the demo's workspace (OUTPUT/ws): WS_ROOT is the output folder.
    const std::filesystem::path exe = server::SelfExecutable();
    std::printf("\n  open it in the console:\n    %s serve %s\n", exe.c_str(),
                std::filesystem::absolute(o->output).lexically_normal().c_str());
  });
}

const RegisterCommand reg(1000, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_demo
