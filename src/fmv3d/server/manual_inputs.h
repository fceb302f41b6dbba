// What the operator enters in the console's hand tools, checked whole before anything is written: tie points
// (WS/manual/tiepoints.json), ground control points (WS/manual/gcp_list.txt, OpenDroneMap's format), the
// calibration window's request and the sensor name it saves under. Pure functions, free of HTTP; every
// failure is a RequestError(400) whose message names the bad item (line, point, observation, field).
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace fmv3d::server {

struct FrameSize {
  std::string name;
  int width = 0, height = 0;
};

// manual/tiepoints.json (docs/manual-inputs.md):
//   {"version": 1,
//    "tiepoints": [{"id": "t1", "observations": [{"image": NAME, "x": px, "y": px}, ...]}],   ≥ 2 images each
//    "points_of_interest": [{"id": "p1", "image": NAME, "x": px, "y": px}],                  single-frame keypoints
//    "removed_matches": [{"image1": NAME, "image2": NAME, "x1", "y1", "x2", "y2"}]}          wrong automatic matches
// Pixel coordinates in fmv3d's convention (origin at the image's top-left corner, pixel centres at +0.5).
// Returns the normalised document (missing arrays added); rejects unknown frames, points outside the image,
// tie points with fewer than 2 observations or two in one frame, duplicate ids, unknown fields.
nlohmann::json ValidateTiePoints(std::string_view body, const std::vector<FrameSize>& frames);
nlohmann::json EmptyTiePoints();

// GCPs as the console shows them: {"crs": "EPSG:N" or a PROJ string, "points": [{"name", "x", "y", "z",
// "check": bool, "observations": [{"image", "x", "y"}]}]}; x/y/z are the file's geo_x geo_y geo_z (for
// EPSG:4326: longitude, latitude, ellipsoidal height).
// gcp_list.txt: first line the CRS ("EPSG:N", "WGS84 UTM 32N" or a PROJ string), then one observation per line:
// "geo_x geo_y geo_z im_x im_y image_name [gcp_name] [check]" (a point whose lines carry the word "check" in
// the eighth column is a check point). Blank lines and lines starting with '#' are skipped.
// Rejects: an unknown CRS (EPSG code PROJ does not know), a line with too few or non-numeric columns (naming
// the line number), an image not in the workspace, a pixel outside the image, a point clicked in fewer than
// 2 frames, one name with two different coordinates.
nlohmann::json ParseGcpText(std::string_view text, const std::vector<FrameSize>& frames);
nlohmann::json GcpsFromJson(std::string_view body, const std::vector<FrameSize>& frames);
std::string FormatGcpText(const nlohmann::json& gcps);

// POST /api/workspaces/{ws}/calibration: {"images": [workspace-relative paths], "board": "9x6" or
// {"cols", "rows"}, "square": metres}.
struct CalibrationRequest {
  std::vector<std::string> images;
  int cols = 9, rows = 6;
  double square = 0.025;
};
CalibrationRequest ParseCalibrationRequest(std::string_view body);
// {"name": NAME}: 1–64 characters of [A-Za-z0-9._ -].
std::string ParseSensorName(std::string_view body);

}  // namespace fmv3d::server
