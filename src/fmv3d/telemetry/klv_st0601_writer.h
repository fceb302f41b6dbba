// MISB ST 0601 encoder (the inverse of klv_st0601.h); the standard's attitude convention is in attitude.h.
//
// EncodeSt0601Packet writes one UAS Datalink Local Set: the 16-byte key, a BER length, the items as
// BER-OID tag + BER length + value with the standard's int-mapped encodings (a value is rounded to the
// nearest code, so it decodes within half a code step), and the checksum item last (tag 1).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

namespace fmv3d::telemetry::klv {

// What one packet carries. Angles in degrees, positions in WGS84 degrees, heights in metres.
struct St0601Record {
  uint64_t unix_time_us = 0;                      // tag 2, microseconds since 1970-01-01 UTC
  double sensor_latitude = 0;                     // tag 13, [-90, 90]
  double sensor_longitude = 0;                    // tag 14, [-180, 180]
  double sensor_true_altitude = 0;                // tag 15, metres MSL, [-900, 19000]
  std::optional<double> sensor_ellipsoid_height;  // tag 75, metres HAE, [-900, 19000]
  double platform_heading = 0;                    // tag 5, wrapped to [0, 360)
  double platform_pitch = 0;                      // tag 90 (full range), [-90, 90]
  double platform_roll = 0;                       // tag 91 (full range), [-90, 90]
  double sensor_relative_azimuth = 0;             // tag 18, wrapped to [0, 360)
  double sensor_relative_elevation = 0;           // tag 19, [-180, 180]
  double sensor_relative_roll = 0;                // tag 20, wrapped to [0, 360)
  double horizontal_fov = 0;                      // tag 16, [0, 180]
  double vertical_fov = 0;                        // tag 17, [0, 180]
  std::optional<double> slant_range;              // tag 21, metres [0, 5e6]
  std::optional<double> frame_center_latitude;    // tag 23
  std::optional<double> frame_center_longitude;   // tag 24
  std::optional<double> frame_center_elevation;   // tag 25, metres MSL
  std::optional<double> frame_center_hae;         // tag 78, metres HAE
};

// The whole packet (key + length + set + checksum). Throws fmv3d::Error when a value is outside its tag's
// range (a latitude of 91°, an altitude of 20 km, a NaN) rather than writing a wrong code.
std::vector<uint8_t> EncodeSt0601Packet(const St0601Record& record);

// Encoding primitives (exposed for tests). Codes are rounded to nearest; out-of-range values and widths other
// than 1-4 bytes throw.
std::vector<uint8_t> EncodeBerLength(uint64_t length);
std::vector<uint8_t> EncodeBerOid(uint64_t value);
uint64_t EncodeUnsignedMapped(double value, size_t bytes, double lo, double hi);  // inverse of MapUnsigned
int64_t EncodeSignedMapped(double value, size_t bytes, double range);             // inverse of MapSigned

}  // namespace fmv3d::telemetry::klv
