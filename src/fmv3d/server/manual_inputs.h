// What the operator enters in the console's hand tools, checked whole before anything is written (the formats
// and their readers are docs/manual-inputs.md, io/tiepoints.h and geo/gcp_list.h): tie points
// (WS/manual/tiepoints.json), ground control points (WS/manual/gcp_list.txt, OpenDroneMap's format), the
// calibration window's request and the sensor name it saves under. Free of HTTP; every failure is a
// RequestError(400) whose message names the bad items (entry, line, field).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "fmv3d/io/tiepoints.h"

namespace fmv3d::server {

// PUT body of tie points (manual/tiepoints.json's JSON) checked against the workspace's frames, then written
// atomically to `path`; returns the document as written.
nlohmann::json SaveTiePoints(std::string_view body, const io::FrameTable& frames, const std::filesystem::path& path);
// The saved document, or an empty one.
nlohmann::json LoadTiePoints(const std::filesystem::path& path);

// GCPs as the console shows them: {"crs": line 1 of gcp_list.txt, "points": [{"name", "x", "y", "z", "check",
// "observations": [{"frame", "x", "y"}]}]}; x/y/z are the file's geo_x geo_y geo_z (for EPSG:4326: longitude,
// latitude, ellipsoidal height).
// From the text of a gcp_list.txt (import) or that JSON (the page's table): parsed and checked by geo/gcp_list
// (CRS known, every line well-formed, frames that exist, pixels inside the image) and every point marked in at
// least 2 frames; then written atomically to `path`. Returns the JSON form of what was written.
nlohmann::json SaveGcpText(std::string_view text, const io::FrameTable& frames, const std::filesystem::path& path);
nlohmann::json SaveGcpJson(std::string_view body, const io::FrameTable& frames, const std::filesystem::path& path);
nlohmann::json LoadGcps(const std::filesystem::path& path);

// POST /api/workspaces/{ws}/calibration: {"images": [workspace-relative paths], "board": "9x6" or
// {"cols", "rows"}, "square": metres}.
// {"images": [workspace paths: ≥ 3 chessboard images, or calibration videos], "board", "square",
//  "drop": [file names of images or video frames to leave out]}
struct CalibrationRequest {
  std::vector<std::string> images;
  std::vector<std::string> drop;
  int cols = 9, rows = 6;
  double square = 0.025;
};
CalibrationRequest ParseCalibrationRequest(std::string_view body);
// {"name": NAME}: 1–64 characters of [A-Za-z0-9._ -].
std::string ParseSensorName(std::string_view body);

}  // namespace fmv3d::server
