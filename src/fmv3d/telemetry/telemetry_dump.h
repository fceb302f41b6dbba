// What `fmv3d telemetry INPUT` prints: all telemetry an input carries, each reader chosen by the input's kind,
// as JSON (the edge of the telemetry module; every reader's typed result is converted here).
//   photo (.jpg/.tif ...)   the EXIF fields as recorded, the drone-dji: XMP fields, and the TelemetrySample
//                           that `fmv3d frames` attaches (or why it was rejected)
//   video                   KLV samples, GPMF samples with a summary of the track's streams and fixes, or the
//                           DJI .SRT beside it — the samples `fmv3d frames` interpolates at its keyframes
//   .srt                    the DJI subtitle samples
//   raw GPMF payload        (.gpmf/.raw/.bin, or any file starting with a DEVC entry) its streams and samples
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/telemetry/photo_telemetry.h"

namespace fmv3d::telemetry {

struct DumpOptions {
  PhotoTelemetryOptions photo;  // altitude datum and fix screening (also applied to GPMF fixes)
};

// Throws fmv3d::Error naming the input when it does not exist or cannot be opened as a video.
nlohmann::json DumpTelemetry(const std::filesystem::path& input, const DumpOptions& options);

}  // namespace fmv3d::telemetry
