// The frames stage (`fmv3d frames INPUT... -o WS`): turns image files, image folders and videos (any mix)
// into WS/frames/ — the kept frames as image files plus frames.json (see frames_index.h).
//
// - Images keep their file name (GIFs are converted to <stem>.png, since later stages read with OpenCV);
//   each distinct (size, EXIF make/model/focal) is one camera. Folders are read non-recursively, by name.
// - Each video is one camera; its keyframes (keyframes.h) are written as <video-stem>-<index, 6 digits>.png.
//   Each kept frame carries the telemetry interpolated at its time (KLV, else a GoPro GPMF track, else a DJI
//   .SRT beside the video); a video's whole telemetry (every packet) goes to frames/telemetry.json (telemetry.h,
//   TelemetryTrack), absent when no video has any.
// - Each photo carries the telemetry of its EXIF GPS / DJI XMP (telemetry/photo_telemetry.h).
// - Position fixes that would georeference wrongly ((0, 0), no lock, DOP or stated accuracy too poor, out of
//   range) are dropped with a count and a warning (telemetry/fix_quality.h); the frame is kept without them.
// - The intrinsics prior of each camera comes from options.prior (the CLI wires calib::PriorFromSources:
//   --camera file, sensor database, EXIF), else f = 1.2 · max(w, h) marked "guess".
// - Nothing is written half-way: everything goes to WS/.frames-staging-<pid>/ and replaces WS/frames/ only
//   when complete; on error the staging folder is removed and an existing WS/frames/ is left untouched.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/ingest/keyframes.h"
#include "fmv3d/io/exif.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/telemetry/photo_telemetry.h"

namespace fmv3d::ingest {

// What the intrinsics prior is chosen from: one camera of the input.
struct CameraGroup {
  int width = 0, height = 0;
  std::string source;  // video file, or the folder/file of the first image
  bool is_video = false;
  double pixel_aspect = 1;  // video sample aspect ratio (pixel width / height); applied after the prior
  io::ExifInfo exif;        // of the first image (empty for videos)
};

// Returns the prior intrinsics (size must be the group's) and where they came from (guess, calibration file,
// sensor database, EXIF). Must not return an invalid camera.
using IntrinsicsPriorFn = std::function<core::Camera(const CameraGroup&, io::PriorSource* prior_source)>;

// f = 1.2 · max(w, h), principal point at the centre, no distortion.
core::Camera GuessPrior(int width, int height);

struct IngestOptions {
  std::filesystem::path workspace;  // frames go to workspace/frames/
  int max_frames = 0;               // 0 = no limit; else at most this many frames in total, chosen evenly
  KeyframeOptions keyframes;
  IntrinsicsPriorFn prior;                     // empty: GuessPrior for every camera
  telemetry::PhotoTelemetryOptions telemetry;  // photo altitude datum; fix screening for photos and GPMF
  void Check() const;
};

// Expands folders to the images and videos they hold (sorted by name). Throws fmv3d::Error naming an input
// that does not exist, or a folder with nothing usable.
std::vector<std::filesystem::path> ExpandInputs(const std::vector<std::filesystem::path>& inputs);

// Runs the stage and returns the index it wrote to WS/frames/frames.json. Throws fmv3d::Error naming the
// file on unreadable/unsupported input or a video without a decodable frame; a damaged video keeps the
// frames decoded before the damage (with a warning).
io::FramesIndex IngestFrames(const std::vector<std::filesystem::path>& inputs, const IngestOptions& options);

}  // namespace fmv3d::ingest
