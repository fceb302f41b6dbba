// `fmv3d reconstruct INPUT... -o WS`: every stage in one command, resumable (see pipeline/reconstruct.h).
#include <cstdio>
#include <memory>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/progress_log.h"
#include "fmv3d/pipeline/reconstruct.h"

namespace fmv3d::app::cmd_reconstruct {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("reconstruct",
                                 "Run every stage (frames → features → match → sparse → dense → mesh → texture) in WS");
  struct Args {
    std::vector<std::string> inputs;
    std::string ws, camera_file, sensor, pairs = "auto", progress_json;
    pipeline::ReconstructOptions opt;
    bool no_report = false, fast = false;
    double max_memory_mb = 2048;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("INPUT", a->inputs, "Image files, image folders, videos (any mix)")->required();
  cmd->add_option("-o,--output", a->ws, "Workspace folder (created; an existing one resumes)")->required();
  cmd->add_option("--camera", a->camera_file, "Calibration file (camera.json or OpenCV YAML)");
  cmd->add_option("--sensor", a->sensor, "Sensor database entry for all inputs (see `fmv3d cameras`)");
  cmd->add_option("--max-frames", a->opt.frames.max_frames, "At most N frames in total (0 = no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--pairs", a->pairs, "auto | exhaustive | sequential | spatial")->capture_default_str();
  cmd->add_option("--from", a->opt.runner.from, "Re-run from this stage on, even if its outputs are up to date");
  cmd->add_option("--until", a->opt.runner.until, "Stop after this stage");
  cmd->add_flag("--fast", a->fast,
                "Video-speed preset: 5000 features, 5 sequential neighbours, dense at 480 px with depth maps and "
                "texture for a covering subset of the frames, Poisson one level coarser (a 60 s 960x540 clip: "
                "~8x faster end to end; bench/RESULTS.md has its accuracy)");
  cmd->add_option("--max-memory", a->max_memory_mb,
                  "MB for the working set of the stages that choose a window: features' images in flight and tiles, "
                  "matching's descriptors, dense's views and fusion maps, mesh's Poisson depth, texture's decoded "
                  "frames (the other stages' peaks: bench/RESULTS.md)")
      ->capture_default_str();
  cmd->add_flag("--no-report", a->no_report, "Skip report/report.html and its pictures");
  cmd->add_option(
      "--progress-json", a->progress_json,
      "Append progress and stage events to FILE as JSON lines (core/progress_log.h; read by `fmv3d serve`)");
  cmd->callback([a] {
    auto& o = a->opt;
    for (const auto& in : a->inputs) o.inputs.emplace_back(in);
    o.workspace = a->ws;
    o.prior.camera_file = a->camera_file;
    o.prior.sensor_name = a->sensor;
    o.match.pairs.mode = features::ParsePairMode(a->pairs);
    o.report = !a->no_report;
    if (a->fast) o.ApplyFastPreset();
    o.SetMaxMemory(a->max_memory_mb);
    if (!a->progress_json.empty()) core::OpenProgressLog(a->progress_json);
    const auto report = pipeline::RunReconstruct(o);
    std::printf("reconstruction in %s\n", a->ws.c_str());
    if (o.report) std::printf("  report: %s/report/report.html\n", a->ws.c_str());
  });
}

const RegisterCommand reg(900, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_reconstruct
