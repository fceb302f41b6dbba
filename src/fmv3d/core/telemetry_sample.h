// One telemetry sample of a video frame or a photo (KLV, DJI SRT, GoPro GPMF, EXIF/XMP: the readers in
// telemetry/), independent of its source: the per-frame record that frames.json carries and that pair
// selection, georeferencing and the console read. Kept in core so that the frames index (io/) holds it typed.
//
// Units: degrees (WGS84 latitude/longitude, angles), metres, seconds. Every field is optional: a packet
// carries what it carries, and an "error"/"N/A" encoding leaves the field empty. `time` is seconds from the
// start of the container (telemetry.h); for a photo, 0.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::core {

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

// The numeric fields by name, with how each is interpolated between two samples (telemetry.h).
enum class TelemetryInterp { kLinear, kAngle360, kLongitude, kNearest };
struct TelemetryField {
  const char* name;
  std::optional<double> TelemetrySample::*field;
  TelemetryInterp interp;
};
const std::vector<TelemetryField>& TelemetryFields();

// Every field equal (absent equals absent).
bool operator==(const TelemetrySample& a, const TelemetrySample& b);
inline bool operator!=(const TelemetrySample& a, const TelemetrySample& b) { return !(a == b); }

// {"time": .., "source": "ST0601", "sensor_latitude": ..., ...}; absent and non-finite fields are omitted.
nlohmann::json ToJson(const TelemetrySample& s);
// The inverse of ToJson; unknown keys are ignored, a null field is absent (JSON's spelling of a non-finite
// number). Throws fmv3d::Error when "time" is missing or a known field is not a number.
TelemetrySample TelemetryFromJson(const nlohmann::json& j);

}  // namespace fmv3d::core
