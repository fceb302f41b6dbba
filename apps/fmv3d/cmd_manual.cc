// `fmv3d manual check WS [--tiepoints FILE] [--gcp FILE] [--json]`: validates the operator's tie points and GCPs
// (docs/manual-inputs.md) against the workspace's frames; prints every problem and exits 1 when any file has one.
#include <cstdio>
#include <optional>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/pipeline/manual_check.h"

namespace fmv3d::app::cmd_manual {
namespace {

void Add(CLI::App& app) {
  auto* manual = app.add_subcommand("manual", "What the operator entered by hand (WS/manual/: tie points, GCPs)");
  manual->require_subcommand(1);
  auto* cmd = manual->add_subcommand("check", "Validate WS/manual/tiepoints.json and WS/manual/gcp_list.txt");
  struct Args {
    std::string ws, tiepoints, gcp;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (with frames/frames.json)")->required();
  cmd->add_option("--tiepoints", a->tiepoints, "Tie-point file to check instead of WS/manual/tiepoints.json");
  cmd->add_option("--gcp", a->gcp, "GCP file (OpenDroneMap gcp_list.txt) instead of WS/manual/gcp_list.txt");
  cmd->add_flag("--json", a->json, "Print the result as JSON (for the console's server)");
  cmd->callback([a] {
    const auto opt = [](const std::string& s) {
      return s.empty() ? std::nullopt : std::optional<std::filesystem::path>(s);
    };
    const auto r = pipeline::CheckManualInputs(a->ws, opt(a->tiepoints), opt(a->gcp));
    if (a->json) {
      std::printf("%s\n", r.ToJson().dump(2).c_str());
    } else {
      for (const auto* f : {&r.tiepoints, &r.gcp}) {
        if (!f->present) {
          std::printf("%s: absent\n", f->path.string().c_str());
          continue;
        }
        for (const auto& e : f->errors) std::fprintf(stderr, "%s\n", e.c_str());
      }
      if (r.tiepoints.valid())
        std::printf("%s: valid: %zu tie points, %zu keypoints, %zu deleted matches\n",
                    r.tiepoints.path.string().c_str(), r.tie_points, r.keypoints, r.deleted_matches);
      if (r.gcp.valid())
        std::printf("%s: valid: CRS %s, %zu GCPs (%zu check points), %zu observations\n", r.gcp.path.string().c_str(),
                    r.crs.c_str(), r.gcp_points, r.check_points, r.gcp_observations);
    }
    if (!r.ok())
      throw Error(std::to_string(r.tiepoints.errors.size() + r.gcp.errors.size()) +
                  " problem(s) in the manual inputs (listed above)");
  });
}

const RegisterCommand reg(690, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_manual
