#include "fmv3d/pipeline/stage_runner.h"

#include <spdlog/spdlog.h>

#include <sys/resource.h>

#include <chrono>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/pipeline/workspace.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

namespace {
int IndexOf(const std::vector<Stage>& stages, const std::string& name, const char* option) {
  if (name.empty()) return -1;
  for (size_t i = 0; i < stages.size(); ++i)
    if (stages[i].name == name) return static_cast<int>(i);
  std::string known;
  for (const auto& s : stages) known += (known.empty() ? "" : ", ") + s.name;
  throw Error(std::string(option) + ": unknown stage '" + name + "' (stages: " + known + ")");
}
}  // namespace

double ProcessCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::vector<StageResult> RunStages(const std::vector<Stage>& stages, const RunnerOptions& options) {
  const int from = IndexOf(stages, options.from, "--from");
  const int until = IndexOf(stages, options.until, "--until");
  std::vector<StageResult> results;
  for (int i = 0; i < static_cast<int>(stages.size()); ++i) {
    if (until >= 0 && i > until) break;
    const Stage& stage = stages[i];
    StageResult r;
    r.name = stage.name;
    const bool forced = from >= 0 && i >= from;
    const fs::path running = options.state_dir.empty() ? fs::path() : options.state_dir / (stage.name + ".running");
    const bool interrupted = !running.empty() && fs::exists(running);
    if (interrupted) spdlog::info("[{}/{}] {}: interrupted in an earlier run, running again", i + 1, stages.size(),
                                  stage.name);
    if (!forced && !interrupted && Workspace::UpToDate({stage.marker}, stage.inputs())) {
      spdlog::info("[{}/{}] {}: up to date, skipped", i + 1, stages.size(), stage.name);
      r.skipped = true;
      results.push_back(r);
      continue;
    }
    spdlog::info("[{}/{}] {} ...", i + 1, stages.size(), stage.name);
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = ProcessCpuSeconds();
    if (!running.empty()) core::WriteTextFile(running, "");
    try {
      r.summary = stage.run();
    } catch (const Error& e) {
      spdlog::error("stage '{}' failed", stage.name);
      throw;
    }
    if (!running.empty()) {
      std::error_code ec;
      fs::remove(running, ec);
      if (ec) throw Error(running.string() + ": cannot remove (" + ec.message() + ")");
    }
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.cpu_seconds = ProcessCpuSeconds() - cpu0;
    spdlog::info("[{}/{}] {} done in {:.1f} s ({:.1f} CPU-s)", i + 1, stages.size(), stage.name, r.seconds,
                 r.cpu_seconds);
    results.push_back(r);
  }
  return results;
}

}  // namespace fmv3d::pipeline
