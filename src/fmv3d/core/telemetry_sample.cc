#include "fmv3d/core/telemetry_sample.h"

#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::core {

const std::vector<TelemetryField>& TelemetryFields() {
  using Interp = TelemetryInterp;
  static const std::vector<TelemetryField> fields = {
      {"sensor_latitude", &TelemetrySample::sensor_latitude, Interp::kLinear},
      {"sensor_longitude", &TelemetrySample::sensor_longitude, Interp::kLongitude},
      {"sensor_altitude_msl", &TelemetrySample::sensor_altitude_msl, Interp::kLinear},
      {"sensor_altitude_hae", &TelemetrySample::sensor_altitude_hae, Interp::kLinear},
      {"sensor_relative_altitude", &TelemetrySample::sensor_relative_altitude, Interp::kLinear},
      {"platform_heading", &TelemetrySample::platform_heading, Interp::kAngle360},
      {"platform_pitch", &TelemetrySample::platform_pitch, Interp::kLinear},
      {"platform_roll", &TelemetrySample::platform_roll, Interp::kLinear},
      {"sensor_relative_azimuth", &TelemetrySample::sensor_relative_azimuth, Interp::kAngle360},
      {"sensor_relative_elevation", &TelemetrySample::sensor_relative_elevation, Interp::kLinear},
      {"sensor_relative_roll", &TelemetrySample::sensor_relative_roll, Interp::kAngle360},
      {"sensor_angle_to_north", &TelemetrySample::sensor_angle_to_north, Interp::kAngle360},
      {"sensor_obliquity", &TelemetrySample::sensor_obliquity, Interp::kAngle360},
      {"gimbal_yaw", &TelemetrySample::gimbal_yaw, Interp::kLongitude},
      {"gimbal_pitch", &TelemetrySample::gimbal_pitch, Interp::kLinear},
      {"gimbal_roll", &TelemetrySample::gimbal_roll, Interp::kLinear},
      {"horizontal_fov", &TelemetrySample::horizontal_fov, Interp::kLinear},
      {"vertical_fov", &TelemetrySample::vertical_fov, Interp::kLinear},
      {"slant_range", &TelemetrySample::slant_range, Interp::kLinear},
      {"frame_center_latitude", &TelemetrySample::frame_center_latitude, Interp::kLinear},
      {"frame_center_longitude", &TelemetrySample::frame_center_longitude, Interp::kLongitude},
      {"frame_center_elevation", &TelemetrySample::frame_center_elevation, Interp::kLinear},
      {"frame_center_hae", &TelemetrySample::frame_center_hae, Interp::kLinear},
      {"gps_dop", &TelemetrySample::gps_dop, Interp::kLinear},
      {"gps_fix", &TelemetrySample::gps_fix, Interp::kNearest},
      {"horizontal_accuracy", &TelemetrySample::horizontal_accuracy, Interp::kLinear},
      {"vertical_accuracy", &TelemetrySample::vertical_accuracy, Interp::kLinear},
      {"rtk_flag", &TelemetrySample::rtk_flag, Interp::kNearest},
      {"camera_orientation_w", &TelemetrySample::camera_orientation_w, Interp::kNearest},
      {"camera_orientation_x", &TelemetrySample::camera_orientation_x, Interp::kNearest},
      {"camera_orientation_y", &TelemetrySample::camera_orientation_y, Interp::kNearest},
      {"camera_orientation_z", &TelemetrySample::camera_orientation_z, Interp::kNearest},
  };
  return fields;
}

bool operator==(const TelemetrySample& a, const TelemetrySample& b) {
  if (a.time != b.time || a.source != b.source || a.unix_time_us != b.unix_time_us) return false;
  for (const auto& f : TelemetryFields())
    if (a.*(f.field) != b.*(f.field)) return false;
  return true;
}

nlohmann::json ToJson(const TelemetrySample& s) {
  nlohmann::json j;
  j["time"] = s.time;
  j["source"] = s.source;
  for (const auto& f : TelemetryFields())
    if (const auto& v = s.*(f.field); v && std::isfinite(*v)) j[f.name] = *v;
  if (s.unix_time_us) j["unix_time_us"] = *s.unix_time_us;
  return j;
}

TelemetrySample TelemetryFromJson(const nlohmann::json& j) {
  if (!j.is_object() || !j.contains("time") || !j["time"].is_number())
    throw Error("telemetry sample without a numeric \"time\"");
  TelemetrySample s;
  s.time = j["time"].get<double>();
  if (j.contains("source") && j["source"].is_string()) s.source = j["source"].get<std::string>();
  for (const auto& f : TelemetryFields()) {
    if (!j.contains(f.name) || j[f.name].is_null()) continue;
    if (!j[f.name].is_number()) throw Error(std::string("telemetry field \"") + f.name + "\" is not a number");
    s.*(f.field) = j[f.name].get<double>();
  }
  if (j.contains("unix_time_us") && j["unix_time_us"].is_number_unsigned())
    s.unix_time_us = j["unix_time_us"].get<uint64_t>();
  return s;
}

}  // namespace fmv3d::core
