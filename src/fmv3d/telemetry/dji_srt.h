// DJI .SRT subtitle telemetry (the file DJI drones write beside each video): one subtitle per frame or per
// second, whose text carries the position. Two layouts are read:
//   older (Phantom 3/4, Inspire):  "GPS(LON,LAT,ALT) BAROMETER:REL_ALT" (units may carry an "M" suffix);
//   newer (Mavic 2/3, Air, Mini):  "[latitude: LAT] [longitude: LON] [rel_alt: R abs_alt: A]" (also
//                                   "[latitude : ..]", "[altitude: A]", "[gb_yaw: .. gb_pitch: .. gb_roll: ..]").
// Each subtitle becomes a TelemetrySample (source "DJI-SRT") at its start time in seconds. A subtitle with
// no position is skipped; a GPS fix of exactly (0, 0) (no satellite lock) is skipped too.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::telemetry {

std::vector<TelemetrySample> ParseDjiSrt(const std::string& text);
// Reads and parses a file; throws fmv3d::Error if it cannot be read.
std::vector<TelemetrySample> ReadDjiSrt(const std::filesystem::path& path);
// The subtitle file beside a video (same stem, ".SRT" or ".srt"), if there is one.
std::optional<std::filesystem::path> FindDjiSrtBeside(const std::filesystem::path& video);

}  // namespace fmv3d::telemetry
