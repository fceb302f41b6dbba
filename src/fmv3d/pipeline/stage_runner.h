// The stage runner behind `fmv3d reconstruct`: each stage declares the files it reads and the one file that
// marks it complete (written last, atomically, by the stage itself). A stage whose marker exists and is newer
// than all its inputs is skipped, so an interrupted run resumes at the first unfinished stage and a changed
// input re-runs everything downstream of it (the later markers become older than the new outputs).
// With a state folder, a stage is also flagged as running (STATE/<name>.running) from its start until it returns:
// a stage killed half-way is re-run on resume even when its marker was already written (a stage may write more
// files after its marker), so a resumed run never builds on a half-finished stage.
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fmv3d::pipeline {

struct Stage {
  std::string name;                                            // "frames", "features", ... (also --until / --from)
  std::function<std::vector<std::filesystem::path>()> inputs;  // evaluated when the stage is reached
  std::filesystem::path marker;                                // the output that proves the stage finished
  std::function<nlohmann::json()> run;                         // runs the stage, returns its summary
};

struct StageResult {
  std::string name;
  bool skipped = false;
  double seconds = 0;
  double cpu_seconds = 0;  // process CPU time (user + system, all threads) spent in the stage
  nlohmann::json summary;  // the stage's summary (null when skipped)
};

struct RunnerOptions {
  std::string from;                 // force re-running from this stage on (empty: resume by timestamps)
  std::string until;                // stop after this stage (empty: all)
  std::filesystem::path state_dir;  // where the running flags live (empty: none, timestamps only)
};

// CPU seconds (user + system, all threads) this process has used so far.
double ProcessCpuSeconds();

// Runs the stages in order. Throws fmv3d::Error for an unknown --from/--until name, and lets a stage's
// error propagate (after logging which stage failed) so the CLI exits non-zero.
std::vector<StageResult> RunStages(const std::vector<Stage>& stages, const RunnerOptions& options);

}  // namespace fmv3d::pipeline
