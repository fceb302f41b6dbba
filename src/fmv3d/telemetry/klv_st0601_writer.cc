#include "fmv3d/telemetry/klv_st0601_writer.h"

#include <fmt/format.h>

#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/klv.h"
#include "fmv3d/telemetry/klv_st0601.h"

namespace fmv3d::telemetry::klv {

namespace {

void PutBigEndian(uint64_t v, size_t bytes, std::vector<uint8_t>* out) {
  for (size_t i = 0; i < bytes; ++i) out->push_back(static_cast<uint8_t>(v >> (8 * (bytes - 1 - i))));
}

class SetBuilder {
 public:
  void Raw(uint64_t tag, const std::vector<uint8_t>& value) {
    const auto t = EncodeBerOid(tag), l = EncodeBerLength(value.size());
    bytes_.insert(bytes_.end(), t.begin(), t.end());
    bytes_.insert(bytes_.end(), l.begin(), l.end());
    bytes_.insert(bytes_.end(), value.begin(), value.end());
  }
  void Uint(uint64_t tag, uint64_t v, size_t n) {
    std::vector<uint8_t> b;
    PutBigEndian(v, n, &b);
    Raw(tag, b);
  }
  void UintMap(uint64_t tag, double v, size_t n, double lo, double hi) {
    Uint(tag, EncodeUnsignedMapped(v, n, lo, hi), n);
  }
  void IntMap(uint64_t tag, double v, size_t n, double range) {
    Uint(tag, static_cast<uint64_t>(EncodeSignedMapped(v, n, range)), n);  // two's complement, truncated to n
  }
  const std::vector<uint8_t>& bytes() const { return bytes_; }

 private:
  std::vector<uint8_t> bytes_;
};

void Require(bool ok, const char* what, double v) {
  if (!ok) throw Error(fmt::format("KLV ST 0601: {} {} is outside the standard's range", what, v));
}

}  // namespace

std::vector<uint8_t> EncodeBerLength(uint64_t length) {
  std::vector<uint8_t> out;
  if (length < 128) {
    out.push_back(static_cast<uint8_t>(length));
    return out;
  }
  size_t n = 0;
  for (uint64_t v = length; v; v >>= 8) ++n;
  out.push_back(static_cast<uint8_t>(0x80 | n));
  PutBigEndian(length, n, &out);
  return out;
}

std::vector<uint8_t> EncodeBerOid(uint64_t value) {
  std::vector<uint8_t> groups;  // 7-bit groups, least significant first
  do {
    groups.push_back(static_cast<uint8_t>(value & 0x7F));
    value >>= 7;
  } while (value);
  std::vector<uint8_t> out;
  for (size_t i = groups.size(); i-- > 0;) out.push_back(static_cast<uint8_t>(groups[i] | (i ? 0x80 : 0)));
  return out;
}

uint64_t EncodeUnsignedMapped(double value, size_t bytes, double lo, double hi) {
  // Up to 4 bytes (every int-mapped ST 0601 tag): wider codes would not be exact in a double.
  if (bytes < 1 || bytes > 4 || !(hi > lo)) throw Error("KLV: bad unsigned mapping");
  Require(std::isfinite(value) && value >= lo && value <= hi, "value", value);
  const double max = std::ldexp(1.0, static_cast<int>(8 * bytes)) - 1.0;
  const double code = std::round((value - lo) / (hi - lo) * max);
  return static_cast<uint64_t>(std::min(code, max));
}

int64_t EncodeSignedMapped(double value, size_t bytes, double range) {
  if (bytes < 1 || bytes > 4 || !(range > 0)) throw Error("KLV: bad signed mapping");
  Require(std::isfinite(value) && std::abs(value) <= range, "value", value);
  const double max = std::ldexp(1.0, static_cast<int>(8 * bytes - 1)) - 1.0;
  const double code = std::clamp(std::round(value / range * max), -max, max);  // never the reserved -2^(8n-1)
  return static_cast<int64_t>(code);
}

std::vector<uint8_t> EncodeSt0601Packet(const St0601Record& r) {
  Require(std::abs(r.sensor_latitude) <= 90, "sensor latitude", r.sensor_latitude);
  Require(std::abs(r.sensor_longitude) <= 180, "sensor longitude", r.sensor_longitude);
  Require(r.sensor_true_altitude >= -900 && r.sensor_true_altitude <= 19000, "sensor altitude", r.sensor_true_altitude);
  Require(std::abs(r.platform_pitch) <= 90, "platform pitch", r.platform_pitch);
  Require(std::abs(r.platform_roll) <= 90, "platform roll", r.platform_roll);
  Require(std::abs(r.sensor_relative_elevation) <= 180, "sensor relative elevation", r.sensor_relative_elevation);
  Require(r.horizontal_fov >= 0 && r.horizontal_fov <= 180, "horizontal field of view", r.horizontal_fov);
  Require(r.vertical_fov >= 0 && r.vertical_fov <= 180, "vertical field of view", r.vertical_fov);
  for (double a : {r.platform_heading, r.sensor_relative_azimuth, r.sensor_relative_roll})
    Require(std::isfinite(a), "angle", a);

  SetBuilder s;
  s.Uint(kTagPrecisionTimestamp, r.unix_time_us, 8);
  s.UintMap(kTagPlatformHeading, Wrap360(r.platform_heading), 2, 0, 360);
  s.IntMap(kTagSensorLatitude, r.sensor_latitude, 4, 90);
  s.IntMap(kTagSensorLongitude, r.sensor_longitude, 4, 180);
  s.UintMap(kTagSensorTrueAltitude, r.sensor_true_altitude, 2, -900, 19000);
  s.UintMap(kTagSensorHfov, r.horizontal_fov, 2, 0, 180);
  s.UintMap(kTagSensorVfov, r.vertical_fov, 2, 0, 180);
  s.UintMap(kTagSensorRelAzimuth, Wrap360(r.sensor_relative_azimuth), 4, 0, 360);
  s.IntMap(kTagSensorRelElevation, r.sensor_relative_elevation, 4, 180);
  s.UintMap(kTagSensorRelRoll, Wrap360(r.sensor_relative_roll), 4, 0, 360);
  if (r.slant_range) {
    Require(*r.slant_range >= 0 && *r.slant_range <= 5e6, "slant range", *r.slant_range);
    s.UintMap(kTagSlantRange, *r.slant_range, 4, 0, 5e6);
  }
  if (r.frame_center_latitude && r.frame_center_longitude) {
    Require(std::abs(*r.frame_center_latitude) <= 90, "frame centre latitude", *r.frame_center_latitude);
    Require(std::abs(*r.frame_center_longitude) <= 180, "frame centre longitude", *r.frame_center_longitude);
    s.IntMap(kTagFrameCenterLatitude, *r.frame_center_latitude, 4, 90);
    s.IntMap(kTagFrameCenterLongitude, *r.frame_center_longitude, 4, 180);
  }
  if (r.frame_center_elevation) {
    Require(*r.frame_center_elevation >= -900 && *r.frame_center_elevation <= 19000, "frame centre elevation",
            *r.frame_center_elevation);
    s.UintMap(kTagFrameCenterElevation, *r.frame_center_elevation, 2, -900, 19000);
  }
  if (r.frame_center_hae) {
    Require(*r.frame_center_hae >= -900 && *r.frame_center_hae <= 19000, "frame centre height above ellipsoid",
            *r.frame_center_hae);
    s.UintMap(kTagFrameCenterHae, *r.frame_center_hae, 2, -900, 19000);
  }
  s.Uint(65, 17, 1);  // UAS Datalink LS version number: ST 0601.17
  if (r.sensor_ellipsoid_height) {
    Require(*r.sensor_ellipsoid_height >= -900 && *r.sensor_ellipsoid_height <= 19000, "sensor ellipsoid height",
            *r.sensor_ellipsoid_height);
    s.UintMap(kTagSensorEllipsoidHeight, *r.sensor_ellipsoid_height, 2, -900, 19000);
  }
  s.IntMap(kTagPlatformPitchFull, r.platform_pitch, 4, 90);
  s.IntMap(kTagPlatformRollFull, r.platform_roll, 4, 90);

  // The checksum covers key, length and set up to and including the checksum's tag and length bytes.
  std::vector<uint8_t> body = s.bytes();
  body.push_back(static_cast<uint8_t>(kTagChecksum));
  body.push_back(2);
  std::vector<uint8_t> out(kSt0601Key.begin(), kSt0601Key.end());
  const auto len = EncodeBerLength(body.size() + 2);
  out.insert(out.end(), len.begin(), len.end());
  out.insert(out.end(), body.begin(), body.end());
  const uint16_t sum = St0601Checksum(ByteSpan(out.data(), out.size()));
  out.push_back(static_cast<uint8_t>(sum >> 8));
  out.push_back(static_cast<uint8_t>(sum & 0xFF));
  return out;
}

}  // namespace fmv3d::telemetry::klv
