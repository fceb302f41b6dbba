// frames/frames.json: the index of a workspace's frames, written by `fmv3d frames` (or `fmv3d synth` for its
// ground truth) and read by every later stage. Frame names are stable (DESIGN.md): an image keeps its file name,
// a video frame is "<video-stem>-<index, 6 digits>.<ext>", the index counted from 0 in decode order.
//
// {
//   "version": 1,
//   "cameras": [ { "id": 1, "width": 1280, "height": 720,
//                  "prior": { "f": 1536, "aspect": 1, "u0": 640, "v0": 360, "k1": 0, "k2": 0, "p1": 0, "p2": 0 },
//                  "prior_source": "guess" | "calibration:FILE" | "sensor-db:NAME" | "exif" | "telemetry-hfov"
//                                  (PriorSource below),
//                  "source": "path/of/video/or/image/folder" } ],
//   "frames":  [ { "name": "flight-000012.png", "camera_id": 1, "source": "flight.mp4", "frame_index": 12,
//                  "timestamp": 0.4, "sharpness": 153.2,
//                  "telemetry": { ... optional: core/telemetry_sample.h, "time" defaults to the timestamp ... } } ]
// }
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/telemetry_sample.h"

namespace fmv3d::io {

// Where a camera's prior intrinsics came from. Decisions use the kind; frames.json's spelling is made and read
// only by PriorSourceName / ParsePriorSource.
enum class PriorKind {
  kNone,           // not recorded (a hand-written or older frames.json): ""
  kGuess,          // f = 1.2 · max(w, h): bundle adjustment must refine f: "guess"
  kExif,           // the EXIF focal length: "exif"
  kSensorDb,       // the sensor database, detail = the sensor's name: "sensor-db:NAME"
  kCalibration,    // a calibration file, detail = its path: "calibration:FILE"
  kTelemetryHfov,  // the telemetry's horizontal field of view: "telemetry-hfov"
  kOther,          // a spelling this version does not know, kept verbatim in detail so it is written back unchanged
};
struct PriorSource {
  PriorKind kind = PriorKind::kNone;
  std::string detail;  // the sensor's name or the calibration file; empty for the other kinds
};
std::string PriorSourceName(const PriorSource& source);
PriorSource ParsePriorSource(const std::string& name);  // never throws: an unknown spelling is kOther

struct CameraPrior {
  core::Camera camera;       // id, size and prior intrinsics
  PriorSource prior_source;  // where the intrinsics came from
  std::string source;        // the video or image set it belongs to
};

struct FrameRecord {
  std::string name;  // file name inside frames/
  uint32_t camera_id = 1;
  std::string source;
  int64_t frame_index = 0;  // decode-order index in a video; 0 for still images
  double timestamp = 0;     // seconds from the start of the video; 0 for still images
  double sharpness = 0;
  std::optional<core::TelemetrySample> telemetry;
};

struct FramesIndex {
  std::vector<CameraPrior> cameras;
  std::vector<FrameRecord> frames;

  const CameraPrior* FindCamera(uint32_t id) const;
};

void WriteFramesIndex(const FramesIndex& index, const std::filesystem::path& path);
// Throws fmv3d::Error naming the file and the problem when it is missing or malformed.
FramesIndex ReadFramesIndex(const std::filesystem::path& path);

}  // namespace fmv3d::io
