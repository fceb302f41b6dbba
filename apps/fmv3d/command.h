// Subcommand registry: each cmd_<name>.cc registers a function that adds its CLI11 subcommand, so adding a
// stage's command never touches main.cc. Commands hold no algorithms: they parse options, call the library
// and report. A command signals failure by throwing fmv3d::Error. Each cmd_<name>.cc keeps its helpers in
// namespace fmv3d::app::cmd_<name>, so a unity build can compile several commands as one translation unit.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

namespace fmv3d::app {

struct CommandEntry {
  int order;  // position in --help: pipeline order (see DESIGN.md)
  std::function<void(CLI::App&)> add;
};

std::vector<CommandEntry>& CommandRegistry();

struct RegisterCommand {
  RegisterCommand(int order, std::function<void(CLI::App&)> add) {
    CommandRegistry().push_back({order, std::move(add)});
  }
};

// Global options, filled before any subcommand callback runs.
struct GlobalOptions {
  int verbosity = 0;
  int threads = 0;
};
const GlobalOptions& Globals();

}  // namespace fmv3d::app
