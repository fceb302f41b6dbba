// WS/manual/tiepoints.json: what the operator clicked — tie points (one ground point seen in ≥ 2 frames),
// single-frame keypoints (points of interest) and automatic matches the operator deleted. The format, the pixel
// convention and the rules are in docs/manual-inputs.md; frame ids are frames.json's frame names, pixels are
// fmv3d's (origin at the image's top-left corner, pixel centres at +0.5).
//
// Parsing and checking collect every problem (one message each, naming the entry) instead of stopping at the
// first, so the console can show them all; the writer refuses to write anything that does not check, and writes
// atomically (nothing saved half-way).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/io/frames_index.h"

namespace fmv3d::io {

inline constexpr const char* kTiePointsFormat = "fmv3d-tiepoints";
inline constexpr int kTiePointsVersion = 1;

struct ImagePoint {
  std::string frame;    // frame name as in frames.json
  double x = 0, y = 0;  // pixels, fmv3d convention
};

struct TiePoint {
  std::string id, label;
  std::vector<ImagePoint> observations;  // ≥ 2, in different frames
};

struct ManualKeypoint {
  std::string id, label;
  ImagePoint point;
};

struct DeletedMatch {
  std::string frame1, frame2;
  uint32_t feature1 = 0, feature2 = 0;  // keypoint indices in features/<frame-stem>.feat
};

struct TiePoints {
  std::vector<TiePoint> tie_points;
  std::vector<ManualKeypoint> keypoints;
  std::vector<DeletedMatch> deleted_matches;
  bool empty() const { return tie_points.empty() && keypoints.empty() && deleted_matches.empty(); }
};

// What a frame id must satisfy: the image size, and (when known) the number of automatic keypoints that deleted
// matches may index.
struct FrameLimits {
  int width = 0, height = 0;
  size_t num_keypoints = std::numeric_limits<size_t>::max();  // max(): unknown (features not extracted)
};
using FrameTable = std::map<std::string, FrameLimits>;
// Every frame of the index with its camera's size.
FrameTable FrameTableOf(const FramesIndex& index);

// Structure only (JSON syntax, format and version, field types, ids, ≥ 2 observations in different frames,
// finite coordinates, non-negative indices): appends one message per problem to *errors. Returns what could be
// read; use it only when *errors stayed empty.
TiePoints ParseTiePoints(const std::string& text, std::vector<std::string>* errors);
TiePoints TiePointsFromJson(const nlohmann::json& j, std::vector<std::string>* errors);
nlohmann::json TiePointsToJson(const TiePoints& tie_points);

// Against a workspace's frames: frames that exist, points inside their image, deleted-match indices below the
// frame's keypoint count. Appends one message per problem.
void CheckTiePoints(const TiePoints& tie_points, const FrameTable& frames, std::vector<std::string>* errors);

// Reads and checks (when `frames` is given); throws fmv3d::Error "<path>: <every problem, one per line>".
TiePoints ReadTiePoints(const std::filesystem::path& path, const FrameTable* frames = nullptr);
// Parse + check + atomic write; on any problem throws fmv3d::Error listing them and leaves `path` untouched.
void WriteTiePoints(const TiePoints& tie_points, const std::filesystem::path& path, const FrameTable* frames = nullptr);

// "first problem; second problem; ... (N more)" for one-line messages.
std::string JoinErrors(const std::vector<std::string>& errors, size_t max_shown = 10);

}  // namespace fmv3d::io
