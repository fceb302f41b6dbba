#include "fmv3d/pipeline/stage_runner.h"

#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <chrono>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/progress_log.h"
#include "fmv3d/core/workspace.h"

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
  nlohmann::json names = nlohmann::json::array();
  for (const auto& s : stages) names.push_back(s.name);
  core::AppendProgressEvent({{"event", "stages"}, {"stages", names}});
  const int count = static_cast<int>(stages.size());
  auto event = [count](const std::string& name, const char* state, int index, double seconds) {
    core::AppendProgressEvent({{"event", "stage"},
                               {"stage", name},
                               {"state", state},
                               {"index", index},
                               {"count", count},
                               {"seconds", seconds}});
  };
  for (int i = 0; i < static_cast<int>(stages.size()); ++i) {
    if (until >= 0 && i > until) break;
    const Stage& stage = stages[i];
    StageResult r;
    r.name = stage.name;
    const bool forced = from >= 0 && i >= from;
    const fs::path running = options.state_dir.empty() ? fs::path() : options.state_dir / (stage.name + ".running");
    const bool interrupted = !running.empty() && fs::exists(running);
    if (interrupted)
      spdlog::info("[{}/{}] {}: interrupted in an earlier run, running again", i + 1, stages.size(), stage.name);
    if (!forced && !interrupted && core::Workspace::UpToDate({stage.marker}, stage.inputs())) {
      spdlog::info("[{}/{}] {}: up to date, skipped", i + 1, stages.size(), stage.name);
      r.skipped = true;
      event(stage.name, "skipped", i, 0);
      results.push_back(r);
      continue;
    }
    spdlog::info("[{}/{}] {} ...", i + 1, stages.size(), stage.name);
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = ProcessCpuSeconds();
    event(stage.name, "start", i, 0);
    if (!running.empty()) core::WriteTextFile(running, "");
    try {
      r.summary = stage.run();
    } catch (const std::exception& e) {
      event(stage.name, "failed", i, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
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
    event(stage.name, "done", i, r.seconds);
    spdlog::info("[{}/{}] {} done in {:.1f} s ({:.1f} CPU-s)", i + 1, stages.size(), stage.name, r.seconds,
                 r.cpu_seconds);
    results.push_back(r);
  }
  return results;
}

}  // namespace fmv3d::pipeline
