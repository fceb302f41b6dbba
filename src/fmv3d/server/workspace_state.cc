#include "fmv3d/server/workspace_state.h"

#include <algorithm>
#include <fstream>

#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/pipeline/reconstruct.h"
#include "fmv3d/server/validation.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

const char* StageStateName(StageState s) {
  switch (s) {
    case StageState::kPending:
      return "pending";
    case StageState::kDone:
      return "done";
    case StageState::kStale:
      return "stale";
    case StageState::kRunning:
      return "running";
    case StageState::kFailed:
      return "failed";
    case StageState::kSkipped:
      return "skipped";
    case StageState::kStopped:
      return "stopped";
  }
  return "pending";
}

std::optional<StageState> ParseStageState(std::string_view name) {
  for (const StageState s : {StageState::kPending, StageState::kDone, StageState::kStale, StageState::kRunning,
                             StageState::kFailed, StageState::kSkipped, StageState::kStopped})
    if (name == StageStateName(s)) return s;
  return std::nullopt;
}

bool IsWorkspace(const fs::path& dir) {
  std::error_code ec;
  const core::Workspace ws(dir);
  return fs::is_regular_file(ws.project_json(), ec) || fs::is_regular_file(ws.frames_json(), ec);
}

std::vector<std::string> ListWorkspaces(const fs::path& ws_root) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(ws_root, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!IsValidWorkspaceName(name) || it->is_symlink(ec) || !it->is_directory(ec)) continue;
    if (IsWorkspace(it->path())) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::vector<std::string> ProjectInputs(const fs::path& ws) {
  std::vector<std::string> inputs;
  try {
    const nlohmann::json p = core::ReadJson(ws / "project.json");
    if (p.contains("inputs") && p["inputs"].is_array())
      for (const auto& in : p["inputs"])
        if (in.is_string()) inputs.push_back(in.get<std::string>());
  } catch (const std::exception&) {
  }
  return inputs;
}

namespace {
std::optional<fs::file_time_type> MTime(const fs::path& p) {
  std::error_code ec;
  const auto t = fs::last_write_time(p, ec);
  if (ec) return std::nullopt;
  return t;
}

StageState StateOf(const fs::path& marker, const std::vector<fs::path>& inputs) {
  const auto m = MTime(marker);
  if (!m) return StageState::kPending;
  for (const auto& in : inputs) {
    const auto t = MTime(in);
    if (t && *t > *m) return StageState::kStale;
  }
  return StageState::kDone;
}
}  // namespace

std::vector<StageStatus> StageStates(const fs::path& ws) {
  pipeline::ReconstructOptions o;
  o.workspace = ws;
  for (const auto& in : ProjectInputs(ws)) o.inputs.emplace_back(in);
  std::vector<StageStatus> out;
  fs::path last_marker;
  for (const auto& stage : pipeline::ReconstructStages(o)) {
    std::vector<fs::path> inputs;
    try {
      inputs = stage.inputs();  // the frames stage lists the input videos, which may have moved: no inputs then
    } catch (const std::exception&) {
    }
    out.push_back({stage.name, StateOf(stage.marker, inputs)});
  }
  const core::Workspace w(ws);
  out.push_back({"report", StateOf(w.report_dir() / "report.json", {w.report_dir() / "texture.json"})});
  return out;
}

namespace {
int CountFrames(const fs::path& frames_json) {
  try {
    const nlohmann::json j = core::ReadJson(frames_json);
    if (j.contains("frames") && j["frames"].is_array()) return static_cast<int>(j["frames"].size());
  } catch (const std::exception&) {
  }
  return 0;
}

// Registered images in a COLMAP images.txt: two lines per image after the comments (the second may be empty).
int CountRegistered(const fs::path& images_txt) {
  std::ifstream in(images_txt);
  if (!in) return 0;
  std::string line;
  int data_lines = 0;
  bool header = true;
  while (std::getline(in, line)) {
    if (header && !line.empty() && line[0] == '#') continue;
    header = false;
    ++data_lines;
  }
  return (data_lines + 1) / 2;
}

nlohmann::json IfExists(const fs::path& ws, const char* rel) {
  std::error_code ec;
  return fs::is_regular_file(ws / rel, ec) ? nlohmann::json(rel) : nlohmann::json();
}
}  // namespace

nlohmann::json DescribeWorkspace(const fs::path& ws, const std::map<std::string, StageState>& job_states) {
  const core::Workspace w(ws);
  nlohmann::json stages = nlohmann::json::array();
  for (auto s : StageStates(ws)) {
    const auto it = job_states.find(s.name);
    if (it != job_states.end() && (it->second == StageState::kRunning || s.state != StageState::kDone))
      s.state = it->second;
    stages.push_back({{"name", s.name}, {"state", StageStateName(s.state)}});
  }
  std::error_code ec;
  return {{"name", ws.filename().string()},
          {"stages", stages},
          {"georeferenced", fs::is_regular_file(w.geo_dir() / "georef.json", ec)},
          {"frames", CountFrames(w.frames_json())},
          {"registered", CountRegistered(w.sparse_dir() / "images.txt")}};
}

nlohmann::json WorkspaceFiles(const fs::path& ws) {
  return {{"sparse_ply", IfExists(ws, "sparse/sparse.ply")},
          {"fused_ply", IfExists(ws, "dense/fused.ply")},
          {"mesh_glb", IfExists(ws, "mesh/model.glb")},
          {"tileset", IfExists(ws, "tiles/tileset.json")},
          {"ortho", IfExists(ws, "geo/ortho.tif")},
          {"dsm", IfExists(ws, "geo/dsm.tif")},
          {"hillshade", IfExists(ws, "geo/hillshade.png")},
          {"report_html", IfExists(ws, "report/report.html")},
          {"compare", IfExists(ws, "report/compare/compare.json")},
          {"cad_error", IfExists(ws, "report/compare/cad_error.ply")}};
}

}  // namespace fmv3d::server
