// `fmv3d manual check WS`: validates what the operator entered (WS/manual/tiepoints.json and
// WS/manual/gcp_list.txt, docs/manual-inputs.md) against the workspace's frames, collecting every problem. The
// console's server calls the command (or this function) before it saves, and shows the messages.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/workspace.h"

namespace fmv3d::pipeline {

struct ManualFileCheck {
  std::filesystem::path path;
  bool present = false;
  std::vector<std::string> errors;  // empty: valid
  bool valid() const { return present && errors.empty(); }
};

struct ManualCheck {
  ManualFileCheck tiepoints, gcp;
  size_t tie_points = 0, keypoints = 0, deleted_matches = 0;  // counts of a readable tiepoints.json
  std::string crs;                                            // of a readable gcp_list.txt
  size_t gcp_points = 0, check_points = 0, gcp_observations = 0;
  // A file that is present and has errors; a missing file is not an error.
  bool ok() const { return tiepoints.errors.empty() && gcp.errors.empty(); }
  nlohmann::json ToJson() const;
};

// Files default to WS/manual/tiepoints.json and WS/manual/gcp_list.txt. Needs WS/frames/frames.json; reads the
// keypoint counts of WS/features/ for the frames that deleted matches name. Never throws for a bad manual file
// (that goes to errors); throws fmv3d::Error when frames.json is missing or unreadable.
ManualCheck CheckManualInputs(const core::Workspace& workspace,
                              const std::optional<std::filesystem::path>& tiepoints = std::nullopt,
                              const std::optional<std::filesystem::path>& gcp_list = std::nullopt);

}  // namespace fmv3d::pipeline
