// Telemetry of a video or a photo, independent of its source (MISB ST 0601 / EG 0104 KLV in MPEG-TS, DJI .SRT
// subtitles, GoPro GPMF in MP4 (gpmf_telemetry.h), EXIF GPS / DJI XMP of photos (photo_telemetry.h)): one
// TelemetrySample (core/telemetry_sample.h) per packet, with its presentation time; interpolation at a frame's
// time.
//
// Units: degrees (WGS84 latitude/longitude, angles), metres, seconds. Every field is optional: a packet
// carries what it carries, and an "error"/"N/A" encoding leaves the field empty.
//
// Times: `time` is seconds from the start of the container (the format's start_time subtracted, the same
// origin as libavformat-based frame timestamps when they subtract it too). A KLV packet without PTS
// (asynchronous metadata) takes the time of the last timed packet before it in the file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/telemetry_sample.h"
#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry {

using core::TelemetryFromJson;
using core::TelemetrySample;
using core::ToJson;

struct TelemetryStats {
  klv::ParseStats klv;
  std::vector<std::pair<int, size_t>> packets_per_stream;  // (stream index, KLV packets kept)
};

// Demuxes every KLV data stream of a media file with libavformat and decodes its packets. Throws
// fmv3d::Error ("FILE: cannot open: ...") when the file cannot be opened or probed; a file without KLV
// streams yields an empty list.
std::vector<klv::Packet> ReadVideoKlv(const std::filesystem::path& path, TelemetryStats* stats = nullptr);

// Telemetry of one decoded packet (ST 0601 or EG0104), nullopt for other standards.
std::optional<TelemetrySample> SampleFromPacket(const klv::Packet& p);

// ReadVideoKlv + SampleFromPacket, sorted by time (stable).
std::vector<TelemetrySample> ReadVideoTelemetry(const std::filesystem::path& path, TelemetryStats* stats = nullptr);

// Telemetry at time t (seconds) from samples sorted by time: linear in positions, altitudes, angles (with
// wrap-around at 360 / longitude at +/-180), FOV, ranges and the timestamp; nearest sample for discrete
// fields and for fields that only one neighbour has. Outside the samples' span it returns the end sample if
// t is within `max_extrapolation` seconds of it, else nullopt (as for an empty list).
std::optional<TelemetrySample> InterpolateTelemetry(const std::vector<TelemetrySample>& samples, double t,
                                                    double max_extrapolation = 0.5);

// The whole telemetry of a video (every packet, not only the kept frames'), so that later stages can use all
// of it: georef fits the model's trajectory to every position (frames.json only carries the keyframes').
// frames/telemetry.json: {"version": 1, "tracks": [{"source": "flight.ts", "samples": [ToJson, ...]}]};
// "source" is the video path exactly as frames.json's frames state it.
struct TelemetryTrack {
  std::string source;
  std::vector<TelemetrySample> samples;  // sorted by time
};
void WriteTelemetryTracks(const std::vector<TelemetryTrack>& tracks, const std::filesystem::path& path);
// Throws fmv3d::Error naming the file when it is unreadable or malformed.
std::vector<TelemetryTrack> ReadTelemetryTracks(const std::filesystem::path& path);

}  // namespace fmv3d::telemetry
