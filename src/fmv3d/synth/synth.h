// Synthetic vision: renders a flight over a fixed scene and writes the frames (or a video) together with the
// exact ground truth. This is what `fmv3d synth` runs; later stages are measured against its output.
//
// Output layout in `output`:
//   frames/flight-000000.png ...   the frames (png or jpg formats), 6-digit index from 0
//   flight.mp4 | flight.ts         the video instead (mp4/ts formats); the frame extractor names its frames
//                                  flight-000000.png ..., the names used in truth/images.txt
//   truth/cameras.txt              COLMAP text model: one OPENCV camera with the exact intrinsics
//   truth/images.txt               one image per frame (world-to-camera pose, name flight-NNNNNN.png, or
//                                  .jpg for the jpg format: the frame files' names) with
//   truth/points3D.txt             the projections of a sample of visible surface points (tracks)
//   depth/flight-NNNNNN.tiff       (with write_depth) 32-bit float depth maps: camera z in metres, 0 = sky
//   scene.obj, scene.mtl, *.png    the scene mesh in world metres (z up) with its textures
//   truth.json                     characteristic_length (tallest building, m), scene bounds, seed, frame
//                                  rate, flight geometry, camera and every option; with klv also
//                                  "geo_origin": {"lat","lon","alt"} (the world is that origin's ENU frame)
//   flight.ts with klv             + a MISB ST 0601 KLV data stream, one packet per frame at the
//                                  frame's PTS, from the truth cameras with GPS/attitude noise (telemetry.h)
//   frames/*.jpg with exif_gps     + EXIF GPS and a DJI-style XMP packet per frame (MakePhotoMetadata), the same
//                                  noise model; truth.json gets the geo origin as with klv
//   flight.mp4 with gpmf           + a GoPro GPMF 'gpmd' track, one payload per second of frames with a GPS5
//                                  (GPS9 with gpmf_gps9) fix per frame and CORI orientations (MakeGpmfPayload)
#pragma once

#include <array>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/synth/degrade.h"
#include "fmv3d/synth/flight.h"
#include "fmv3d/synth/scene.h"
#include "fmv3d/synth/telemetry.h"

namespace fmv3d::synth {

enum class OutputFormat { kPng, kJpg, kMp4, kTs };
// The spelling of the command line, truth/truth.json and the files' extension: "png", "jpg", "mp4", "ts".
const char* OutputFormatName(OutputFormat format);
// Throws fmv3d::Error naming the accepted spellings.
OutputFormat ParseOutputFormat(const std::string& name);

struct SynthOptions {
  SceneKind scene = SceneKind::kBuilding;
  FlightOptions flight;
  int width = 1280, height = 720;
  std::optional<double> focal;                   // pixels; default: 60° horizontal field of view
  std::array<double, 4> distortion{0, 0, 0, 0};  // k1 k2 p1 p2
  std::array<double, 2> principal_offset{0, 0};  // true principal point minus the image centre, pixels
  // Sun, exposure, noise (default 1.5 DN), supersampling.
  render::RenderOptions render = [] {
    render::RenderOptions r;
    r.noise_sigma = 1.5;
    return r;
  }();
  OutputFormat format = OutputFormat::kPng;
  int jpeg_quality = 92;
  double fps = 10;
  double detail = 1.0;      // scene texture resolution multiplier
  int truth_points = 3000;  // surface points sampled for points3D.txt (0: none)
  bool write_scene = true;  // scene.obj + textures
  bool write_depth = false;
  bool klv = false;                       // MPEG-TS with ST 0601 telemetry (needs format ts)
  bool exif_gps = false;                  // JPEG frames with EXIF GPS + DJI XMP (needs format jpg)
  bool gpmf = false;                      // MP4 with a GPMF telemetry track (needs format mp4)
  bool gpmf_gps9 = false;                 // the GPMF track carries GPS9 instead of GPS5
  KlvTelemetryOptions klv_options;        // geo origin, GPS / attitude noise of every telemetry kind (fps and
                                          // seed are set from this struct's fps and flight.seed)
  std::vector<FrameDegradation> degrade;  // frames degraded on purpose (synth/degrade.h)
  std::filesystem::path output;

  void Check() const;
  nlohmann::json ToJson() const;
  bool IsVideo() const { return format == OutputFormat::kMp4 || format == OutputFormat::kTs; }
  bool HasTelemetry() const { return klv || exif_gps || gpmf; }
};

// The camera the flight uses: focal from options or a 60° horizontal field of view, principal point at the
// image centre plus principal_offset, the given distortion.
core::Camera SynthCamera(const SynthOptions& options);

// Frame file name for index i: flight-000042.png (always .png for video, as the frame extractor names them).
std::string FrameName(int index, const std::string& extension = "png");

struct SynthResult {
  core::Reconstruction truth;
  double characteristic_length = 0;
  int frames = 0;
  // The telemetry truth + noise, one record per frame (with klv, exif_gps or gpmf): what the KLV stream carries,
  // and what the EXIF / GPMF writers take their positions and attitudes from.
  std::vector<telemetry::klv::St0601Record> klv;
};

// Renders and writes everything (see the layout above). Throws fmv3d::Error on bad options or I/O errors.
SynthResult RunSynth(const SynthOptions& options);

}  // namespace fmv3d::synth
