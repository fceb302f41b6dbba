// MISB EG 0104 (Predator UAV Basic Universal Metadata Set): a universal set of 16-byte keys (matched
// ignoring the registry version byte) with IEEE big-endian floats/doubles, strings and a uint64
// microsecond timestamp.
#pragma once

#include <string>
#include <vector>

#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry::klv {

extern const UlKey kEg0104Key;  // 06 0E 2B 34 02 01 01 01 0E 01 01 02 01 01 00 00

// Item keys the telemetry reader uses.
enum class Eg0104Field {
  kUnknown,
  kUserDefinedTimestamp,
  kEpisodeNumber,
  kPlatformHeading,
  kPlatformPitch,
  kPlatformRoll,
  kDeviceDesignation,
  kImageSourceDevice,
  kImageCoordinateSystem,
  kDeviceLatitude,
  kDeviceLongitude,
  kDeviceAltitude,
  kHorizontalFov,
  kVerticalFov,
  kSlantRange,
  kTargetWidth,
  kFrameCenterLatitude,
  kFrameCenterLongitude,
  kFrameCenterElevation,
  kCornerLatitude1,
  kCornerLatitude2,
  kCornerLatitude3,
  kCornerLatitude4,
  kCornerLongitude1,
  kCornerLongitude2,
  kCornerLongitude3,
  kCornerLongitude4,
  kSecurityLocalSet,
  kStartDatetime,
  kEventStartDatetime,
  kSensorRollAngle,
  kAngleToNorth,
  kObliquityAngle,
};

bool DecodeEg0104Packet(ByteSpan set, Packet* out, ParseStats* stats);
Eg0104Field Eg0104FieldOf(const UlKey& key);
std::string Eg0104KeyName(const UlKey& key);  // "Device Latitude", or "Unknown Key"
// The key of a field (with the version byte of the standard's table).
UlKey Eg0104KeyOf(Eg0104Field f);

}  // namespace fmv3d::telemetry::klv
