// Jobs of the console: `fmv3d reconstruct` runs of our own binary, started with an argv list (fork + exec,
// never a shell), one at a time per workspace. The child writes its log (stdout + stderr) to WS/jobs/ID.log and
// its progress events to WS/jobs/ID.progress.jsonl (core/progress_log.h); one monitor thread tails both, keeps
// each job's state, and publishes `job`, `progress` and `log` events (events.h). Stop = SIGTERM, then SIGKILL
// after the grace period. When a job ends its JOB record is written beside them (WS/jobs/ID-TIME.json), so a
// restarted server rebuilds the finished jobs from these files (RestoreHistory) and numbers new ones after them.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "fmv3d/server/events.h"
#include "fmv3d/server/validation.h"
#include "fmv3d/server/workspace_state.h"

namespace fmv3d::server {

enum class JobState { kQueued, kRunning, kDone, kFailed, kStopped };
const char* JobStateName(JobState s);
std::optional<JobState> ParseJobState(std::string_view name);  // nullopt for an unknown name

// The argv of a reconstruct run (argv[0] = executable): inputs, -o WS, --from/--until (omitted for "report",
// which reconstruct always writes last), --fast, --progress-json.
std::vector<std::string> ReconstructArgv(const std::filesystem::path& executable,
                                         const std::vector<std::filesystem::path>& inputs,
                                         const std::filesystem::path& ws, const JobRequest& request,
                                         const std::filesystem::path& progress_json);

struct JobManagerOptions {
  std::filesystem::path executable;  // the fmv3d binary the jobs run
  double stop_grace_s = 5;           // SIGTERM → SIGKILL
  size_t log_lines = 500;            // kept per job (GET /api/jobs/{id})
};

class JobManager {
 public:
  JobManager(JobManagerOptions options, EventHub* hub);
  ~JobManager();  // stops running jobs (SIGTERM, SIGKILL after the grace period) and joins the monitor
  JobManager(const JobManager&) = delete;
  JobManager& operator=(const JobManager&) = delete;

  // Starts a job in workspace `ws_dir` (named `workspace`) on `inputs` (already resolved). Throws
  // RequestError(409) when a job of that workspace is running, RequestError(500) when the process cannot start.
  nlohmann::json Start(const std::string& workspace, const std::filesystem::path& ws_dir,
                       const std::vector<std::filesystem::path>& inputs, const JobRequest& request);
  // Throws RequestError(409) when a job of `workspace` is running (checked again by Start).
  void RequireIdle(const std::string& workspace) const;
  nlohmann::json List() const;  // every job, oldest first
  std::optional<nlohmann::json> Get(const std::string& id, bool with_log) const;
  std::optional<nlohmann::json> Stop(const std::string& id);
  // Rebuilds the jobs of earlier server runs from each workspace's job files (name, folder): ID-TIME.log, its
  // .progress.jsonl and the .json record written when the job ended. A job without a record (the server died
  // while it ran) is "stopped" with no exit code. New ids continue after the highest id seen. Call before any Start.
  void RestoreHistory(const std::vector<std::pair<std::string, std::filesystem::path>>& workspaces);
  // The workspace's latest job (null when none) and the stage states it overrides (running / failed).
  nlohmann::json LatestFor(const std::string& workspace) const;
  std::map<std::string, StageState> StageOverrides(const std::string& workspace) const;

 private:
  struct StageProgress {
    std::string name;
    StageState state = StageState::kPending;
    double done = 0, total = 0, eta_s = 0;
  };
  struct Job {
    std::string id, workspace;
    pid_t pid = -1;
    JobState state = JobState::kQueued;
    std::string stage;
    std::vector<StageProgress> stages;
    double started = 0, finished = 0;
    std::optional<int> exit_code;
    std::deque<std::string> log;
    std::filesystem::path log_path, progress_path;
    uint64_t log_offset = 0, progress_offset = 0;
    std::string log_partial, progress_partial;
    double stop_requested = 0;  // Unix seconds, 0 = not asked
    bool killed = false;
  };
  nlohmann::json ToJson(const Job& job, bool with_log) const;
  void MonitorLoop();
  void Poll(Job& job);                                                // with mutex_ held
  void Publish(const std::string& type, const nlohmann::json& data);  // not while replaying history
  std::unique_ptr<Job> RestoreJob(const std::string& workspace, const std::filesystem::path& log_path);
  void HandleProgressLine(Job& job, const std::string& line);
  void HandleLogLine(Job& job, const std::string& line);
  StageProgress* FindStage(Job& job, const std::string& name);

  JobManagerOptions options_;
  EventHub* hub_;
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<Job>> jobs_;
  int next_id_ = 1;
  bool replaying_ = false;
  std::atomic<bool> quit_{false};
  std::thread monitor_;
};

}  // namespace fmv3d::server
