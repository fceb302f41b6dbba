// What the console shows of a workspace folder (docs/console-api.md, GET /api/workspaces): each stage's state
// from the stage runner's markers (pipeline/reconstruct.cc's stage list, plus report/report.json), frame and
// camera counts, and the product files present. Reads files only; the caller passes the latest job's overlay.
#pragma once

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace fmv3d::server {

// A stage's state as the console shows it: from the markers (pending, done, stale) or from a job's progress
// events (running, done, skipped, failed; stopped when the job was stopped while it ran).
enum class StageState { kPending, kDone, kStale, kRunning, kFailed, kSkipped, kStopped };
const char* StageStateName(StageState s);
std::optional<StageState> ParseStageState(std::string_view name);  // nullopt for an unknown name

struct StageStatus {
  std::string name;
  StageState state = StageState::kPending;
};

// True when `dir` is a workspace: it holds project.json or frames/frames.json.
bool IsWorkspace(const std::filesystem::path& dir);
// The workspace folder names under `ws_root` (valid names only), sorted.
std::vector<std::string> ListWorkspaces(const std::filesystem::path& ws_root);

// done: the marker exists and is newer than every existing input; stale: older than one; pending: absent.
std::vector<StageStatus> StageStates(const std::filesystem::path& ws);

// {"name", "stages": [{"name", "state"}], "georeferenced", "frames", "registered"} (no "job"). A stage in
// `job_states` (the latest job's running or failed stages) shows that state when it is running, or when the
// markers do not say done.
nlohmann::json DescribeWorkspace(const std::filesystem::path& ws,
                                 const std::map<std::string, StageState>& job_states = {});
// {"sparse_ply", "fused_ply", "mesh_glb", "tileset", "ortho", "dsm", "hillshade", "report_html", "compare",
// "cad_error"}: paths relative to
// the workspace, null when absent.
nlohmann::json WorkspaceFiles(const std::filesystem::path& ws);
// The inputs recorded in WS/project.json (absolute paths), empty when none.
std::vector<std::string> ProjectInputs(const std::filesystem::path& ws);

}  // namespace fmv3d::server
