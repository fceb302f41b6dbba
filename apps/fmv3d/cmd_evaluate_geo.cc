// `fmv3d evaluate-geo WS --truth SYNTH_DIR`: absolute accuracy of a georeferenced workspace (cameras, points,
// DSM) against a `fmv3d synth --klv` ground truth → WS/report/geo_eval.json (and stdout).
#include <iostream>

#include "command.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/evaluation.h"

namespace fmv3d::app::cmd_evaluate_geo {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate-geo", "Georeference / DSM accuracy against a synth --klv truth");
  auto ws = std::make_shared<std::string>();
  auto truth = std::make_shared<std::string>();
  cmd->add_option("WS", *ws, "Workspace folder (after georef, optionally dsm)")->required();
  cmd->add_option("--truth", *truth, "Output folder of `fmv3d synth --klv`")->required();
  cmd->callback([ws, truth] {
    const auto j = geo::EvaluateGeoAgainstSynth(*ws, *truth);
    core::EnsureDirectory(core::Workspace(*ws).report_dir());
    core::WriteJson(core::Workspace(*ws).report_dir() / "geo_eval.json", j);
    std::cout << j.dump(2) << "\n";
  });
}

const RegisterCommand reg(960, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_evaluate_geo
