// Telemetry of a video or a photo, independent of its source (MISB ST 0601 / EG 0104 KLV in MPEG-TS, DJI .SRT
// subtitles, GoPro GPMF in MP4 (gpmf_telemetry.h), EXIF GPS / DJI XMP of photos (photo_telemetry.h)): one
// TelemetrySample per packet, with its presentation time; interpolation at a frame's time; the JSON that
// frames.json carries per frame ("telemetry").
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

#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry {

struct TelemetrySample {
  double time = 0;     // seconds, see above
  std::string source;  // "ST0601", "EG0104", "DJI-SRT", "GPMF", "EXIF", "EXIF+DJI-XMP"

  std::optional<double> sensor_latitude, sensor_longitude;
  std::optional<double> sensor_altitude_msl;       // ST 0601 tag 15 "true altitude" (MSL); EG0104 device altitude
                                                   // (MSL); DJI abs_alt / GPS altitude
  std::optional<double> sensor_altitude_hae;       // ST 0601 tag 75 / 104 (height above WGS84 ellipsoid)
  std::optional<double> sensor_relative_altitude;  // DJI rel_alt / BAROMETER: above the take-off point

  std::optional<double> platform_heading, platform_pitch, platform_roll;
  // Sensor pointing relative to the platform (ST 0601 tags 18-20). For EG0104 the azimuth is derived as
  // angle_to_north - platform_heading (wrapped to [0, 360)); the raw EG0104 angles are kept too.
  std::optional<double> sensor_relative_azimuth, sensor_relative_elevation, sensor_relative_roll;
  std::optional<double> sensor_angle_to_north, sensor_obliquity;  // EG0104 only
  std::optional<double> gimbal_yaw, gimbal_pitch, gimbal_roll;    // DJI gb_yaw/gb_pitch/gb_roll (absolute)

  std::optional<double> horizontal_fov, vertical_fov;
  std::optional<double> slant_range;
  std::optional<double> frame_center_latitude, frame_center_longitude;
  std::optional<double> frame_center_elevation;  // MSL (ST 0601 tag 25, EG0104)
  std::optional<double> frame_center_hae;        // ST 0601 tag 78

  // Fix quality as the source states it (fix_quality.h screens on it).
  std::optional<double> gps_dop;              // dilution of precision (EXIF GPSDOP, GPMF GPSP / 100 or GPS9)
  std::optional<double> gps_fix;              // 0 no lock, 2 = 2D, 3 = 3D (GPMF GPSF / GPS9, EXIF GPSMeasureMode)
  std::optional<double> horizontal_accuracy;  // metres, 1σ (EXIF GPSHPositioningError, DJI RTK std dev)
  std::optional<double> vertical_accuracy;    // metres, 1σ (DJI RtkStdHgt)
  std::optional<double> rtk_flag;             // DJI RtkFlag: 0 none, 16 single point, 34 float, 50 fixed
  // GoPro CORI: the camera's orientation relative to its orientation at the start of the recording (unit
  // quaternion w, x, y, z in the camera's own frame); not an absolute attitude.
  std::optional<double> camera_orientation_w, camera_orientation_x, camera_orientation_y, camera_orientation_z;

  std::optional<uint64_t> unix_time_us;  // ST 0601 precision timestamp / EG0104 user-defined timestamp / GPS UTC
};

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

// {"time": .., "source": "ST0601", "sensor_latitude": ..., ...}; absent fields are omitted.
nlohmann::json ToJson(const TelemetrySample& s);
// The inverse of ToJson; unknown keys are ignored. Throws fmv3d::Error when "time" is missing or a known
// field is not a number.
TelemetrySample TelemetryFromJson(const nlohmann::json& j);

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
