// fmv3d command line: global options, the registered subcommands, and the error policy:
// usage errors → message + usage on stderr, exit 2; fmv3d::Error at run time → one line on stderr, exit 1.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <csignal>
#include <iostream>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/io/huge_pages.h"

namespace fmv3d::app {

std::vector<CommandEntry>& CommandRegistry() {
  static std::vector<CommandEntry> registry;
  return registry;
}

namespace {
GlobalOptions g_globals;
}
const GlobalOptions& Globals() { return g_globals; }

}  // namespace fmv3d::app

int main(int argc, char** argv) {
  using namespace fmv3d;
  // A file-size limit (RLIMIT_FSIZE) then fails the write with EFBIG, which the writers report, instead of
  // killing the process without a word.
  std::signal(SIGXFSZ, SIG_IGN);
  io::UseHugePagesForLargeMatrices();
  CLI::App app{"fmv3d: 3D terrain and target models from UAV full-motion video and photos", "fmv3d"};
  app.set_version_flag("--version", std::string("fmv3d ") + FMV3D_VERSION);
  app.require_subcommand(0, 1);
  app.fallthrough();
  bool verbose = false, quiet = false;
  app.add_flag("-v,--verbose", verbose, "Debug logging");
  app.add_flag("-q,--quiet", quiet, "Errors only");
  app.add_option("--threads", app::g_globals.threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
  app.parse_complete_callback([&] {
    app::g_globals.verbosity = quiet ? -1 : verbose ? 1 : 0;
    core::SetupLogging(app::g_globals.verbosity);
    core::SetNumThreads(app::g_globals.threads);
  });

  auto& registry = app::CommandRegistry();
  std::stable_sort(registry.begin(), registry.end(), [](auto& a, auto& b) { return a.order < b.order; });
  for (auto& entry : registry) entry.add(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "fmv3d: " << e.what() << "\n\n";
    // Show the usage of the subcommand the user was typing, if any.
    const CLI::App* target = &app;
    for (const auto* sub : app.get_subcommands()) target = sub;
    std::cerr << target->help();
    return 2;
  } catch (const Error& e) {
    std::cerr << "fmv3d: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "fmv3d: internal error: " << e.what() << "\n";
    return 1;
  }
  if (app.get_subcommands().empty()) {
    std::cerr << "fmv3d: a subcommand is required\n\n" << app.help();
    return 2;
  }
  return 0;
}
