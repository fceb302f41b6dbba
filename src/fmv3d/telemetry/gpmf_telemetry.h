// GoPro GPMF telemetry of a video: the `gpmd` data track of an MP4/MOV demuxed with libavformat, each sample
// (about one second of metadata) parsed by gpmf.h, and its position streams turned into TelemetrySamples.
//
// Positions: GPS5 (lat, lon, alt, 2D speed, 3D speed) with its stream's GPSF fix and GPSP precision; GPS9
// (lat, lon, alt, 2D speed, 3D speed, days since 2000, seconds since midnight, DOP, fix) with a fix, DOP and
// UTC time per sample; and any other device's stream that describes itself as a position (STNM/TYPE/SCAL/UNIT:
// its first three elements in units "deg", "deg", "m", or a name that names latitude and longitude).
// Altitudes are WGS84 ellipsoidal heights, as the GPMF specification defines GPS5/GPS9, unless the stream's
// GPSA says "MSLV" (mean sea level) — they go to sensor_altitude_hae or sensor_altitude_msl accordingly.
// Timing: the k-th of n samples of a payload with presentation time t and duration d is at t + k·d/n (the
// same clock as the video frames: seconds from the container start).
// Orientation: CORI (camera orientation quaternion w, x, y, z relative to the first frame) is attached to each
// position sample from the nearest CORI sample in time (camera_orientation_w/x/y/z); without positions the
// CORI samples become samples of their own.
// Screening: every position passes ScreenFix (fix_quality.h); rejected fixes are counted, never kept.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "fmv3d/telemetry/fix_quality.h"
#include "fmv3d/telemetry/gpmf.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::telemetry {

struct GpmfPayload {
  double time = 0;      // seconds from the container start
  double duration = 0;  // seconds (0 when unknown: the next payload's time, else 1 s, is used)
  std::vector<uint8_t> bytes;
};

// Every sample of every `gpmd` data stream, in file order. Throws fmv3d::Error ("FILE: cannot open: ...") when
// the file cannot be opened; a file without a gpmd track yields an empty list.
std::vector<GpmfPayload> ReadGpmfPayloads(const std::filesystem::path& video);

struct GpmfTelemetry {
  std::vector<TelemetrySample> samples;  // sorted by time, screened
  FixCounts fixes;                       // position fixes kept / dropped by ScreenFix
  gpmf::ParseStats parse;
  size_t payloads = 0;
  std::map<std::string, size_t> stream_samples;     // data key → samples read (GPS5, ACCL, GYRO, CORI, ...)
  std::map<std::string, std::string> stream_names;  // data key → STNM
  std::vector<std::string> devices;                 // DVNM of every device seen
};

GpmfTelemetry TelemetryFromGpmf(const std::vector<GpmfPayload>& payloads, const FixQualityOptions& fix = {});

// ReadGpmfPayloads + TelemetryFromGpmf.
GpmfTelemetry ReadGpmfTelemetry(const std::filesystem::path& video, const FixQualityOptions& fix = {});

}  // namespace fmv3d::telemetry
