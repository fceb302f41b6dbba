// MISB ST 0601 (UAS Datalink Local Set): tag dictionary and decoder. Values are decoded to engineering
// units (degrees, metres, m/s, ...) with the standard's mappings: unsigned/signed int-mapped fields, ST 1201
// IMAPB fields, strings, enumerations; the reserved "error" value of a signed mapping decodes to null.
// Nested sets: tag 48 (ST 0102 security) is decoded; tags 100/101 (ST 1607 segment/amend, which reuse the
// ST 0601 dictionary) are decoded recursively (depth-limited); other sub-standards (RVT, VMTI, SAR, range
// image, ...) and packs are kept as raw bytes ("value-unparsed-bytes").
#pragma once

#include <string>
#include <vector>

#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry::klv {

extern const UlKey kSt0601Key;  // 06 0E 2B 34 02 0B 01 01 0E 01 03 01 01 00 00 00

// Tags the telemetry reader uses.
enum St0601Tag : uint64_t {
  kTagChecksum = 1,
  kTagPrecisionTimestamp = 2,
  kTagPlatformHeading = 5,
  kTagPlatformPitch = 6,
  kTagPlatformRoll = 7,
  kTagSensorLatitude = 13,
  kTagSensorLongitude = 14,
  kTagSensorTrueAltitude = 15,
  kTagSensorHfov = 16,
  kTagSensorVfov = 17,
  kTagSensorRelAzimuth = 18,
  kTagSensorRelElevation = 19,
  kTagSensorRelRoll = 20,
  kTagSlantRange = 21,
  kTagFrameCenterLatitude = 23,
  kTagFrameCenterLongitude = 24,
  kTagFrameCenterElevation = 25,
  kTagSecurityLocalSet = 48,
  kTagSensorEllipsoidHeight = 75,
  kTagFrameCenterHae = 78,
  kTagPlatformPitchFull = 90,
  kTagPlatformRollFull = 91,
  kTagSensorEllipsoidHeightExtended = 104,
};

// Decodes a whole top-level ST 0601 packet. `whole` spans key + length + set (for the checksum), `set` the
// local set. Returns false (and counts it) on a bad checksum, a missing/misplaced checksum or a set whose
// lengths do not add up.
bool DecodeSt0601Packet(ByteSpan whole, ByteSpan set, Packet* out, ParseStats* stats);
// Decodes a local set body with the ST 0601 dictionary (no checksum); false if its lengths do not add up.
bool DecodeSt0601Items(ByteSpan set, std::vector<Item>* items, ParseStats* stats, int depth = 0);

std::string St0601TagName(uint64_t tag);
// Name of an enumerated value ("Medium" for tag 63 value 2), empty if the tag has no enumeration or the
// value is not listed.
std::string St0601EnumName(uint64_t tag, uint64_t value);

}  // namespace fmv3d::telemetry::klv
