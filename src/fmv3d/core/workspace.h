// A workspace folder: one per reconstruction (DESIGN.md "Workspace"). The layout lives here and only here; each
// stage reads and writes its files through these paths. A path converts implicitly, so a stage called with a
// folder name (tests, the CLI) gets its workspace.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace fmv3d::core {

class Workspace {
 public:
  Workspace(std::filesystem::path root) : root_(std::move(root)) {}  // NOLINT(google-explicit-constructor)
  Workspace(const std::string& root) : root_(root) {}                // NOLINT(google-explicit-constructor)
  Workspace(const char* root) : root_(root) {}                       // NOLINT(google-explicit-constructor)
  const std::filesystem::path& root() const { return root_; }
  std::string name() const { return root_.string(); }  // for messages: "WS: ..."
  std::filesystem::path project_json() const { return root_ / "project.json"; }

  std::filesystem::path frames_dir() const { return root_ / "frames"; }
  std::filesystem::path frames_json() const { return frames_dir() / "frames.json"; }
  std::filesystem::path telemetry_json() const { return frames_dir() / "telemetry.json"; }  // whole tracks
  std::filesystem::path features_dir() const { return root_ / "features"; }
  std::filesystem::path matches_dir() const { return root_ / "matches"; }
  std::filesystem::path sparse_dir() const { return root_ / "sparse"; }
  std::filesystem::path dense_dir() const { return root_ / "dense"; }
  std::filesystem::path mesh_dir() const { return root_ / "mesh"; }
  std::filesystem::path geo_dir() const { return root_ / "geo"; }
  std::filesystem::path georef_json() const { return geo_dir() / "georef.json"; }
  std::filesystem::path sparse_enu_dir() const { return geo_dir() / "sparse_enu"; }
  std::filesystem::path sparse_image_only_dir() const { return geo_dir() / "sparse_image_only"; }
  std::filesystem::path manual_dir() const { return root_ / "manual"; }
  std::filesystem::path report_dir() const { return root_ / "report"; }
  // Held (flock) by the process that runs stages on this workspace; see core::FileLock.
  std::filesystem::path lock_file() const { return root_ / ".lock"; }
  // The stage runner's flags (which stage was running when a run was killed).
  std::filesystem::path state_dir() const { return root_ / ".stages"; }

  // Throws fmv3d::Error ("WS: frames/frames.json is missing; run `fmv3d frames` first") when a stage's input is
  // absent.
  void Require(const std::filesystem::path& input, const char* producing_command) const;
  // True when every output exists and is newer than every input (the stage can be skipped on resume).
  static bool UpToDate(const std::vector<std::filesystem::path>& outputs,
                       const std::vector<std::filesystem::path>& inputs);

 private:
  std::filesystem::path root_;
};

}  // namespace fmv3d::core
