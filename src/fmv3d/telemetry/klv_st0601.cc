#include "fmv3d/telemetry/klv_st0601.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/telemetry/klv_decode_util.h"
#include "fmv3d/telemetry/klv_st0102.h"

namespace fmv3d::telemetry::klv {

const UlKey kSt0601Key = {0x06, 0x0E, 0x2B, 0x34, 0x02, 0x0B, 0x01, 0x01,
                          0x0E, 0x01, 0x03, 0x01, 0x01, 0x00, 0x00, 0x00};

namespace {

enum class Kind {
  kUint,     // raw unsigned integer, 1..8 bytes (length = max, 0 = any up to 8)
  kInt,      // raw signed integer
  kUintMap,  // unsigned mapped onto [a, b], fixed length
  kIntMap,   // signed mapped onto [-b, b], fixed length, 0x80.. = error -> null
  kImapb,    // ST 1201 IMAPB(a, b), variable length
  kString,
  kEnum,  // uint8 with names
  kChecksum,
  kSt0102,  // nested security set
  kNested,  // nested set with the ST 0601 dictionary (ST 1607 segment / amend)
  kBytes,   // kept raw (pack or sub-standard we do not decode)
};

struct TagSpec {
  uint16_t tag;
  const char* name;
  Kind kind;
  uint8_t length;  // required length for fixed-length kinds; max length for kUint/kInt (0 = 8)
  double a, b;
};

// Names follow KWIVER's spelling where klv_gold.json shows it (so dumps compare), else ST 0601.17.
const TagSpec kSpecs[] = {
    {1, "Checksum", Kind::kChecksum, 2, 0, 0},
    {2, "Precision Timestamp", Kind::kUint, 8, 0, 0},
    {3, "Mission ID", Kind::kString, 0, 0, 0},
    {4, "Platform Tail Number", Kind::kString, 0, 0, 0},
    {5, "Platform Heading Angle", Kind::kUintMap, 2, 0, 360},
    {6, "Platform Pitch Angle", Kind::kIntMap, 2, 0, 20},
    {7, "Platform Roll Angle", Kind::kIntMap, 2, 0, 50},
    {8, "Platform True Airspeed", Kind::kUint, 1, 0, 0},
    {9, "Platform Indicated Airspeed", Kind::kUint, 1, 0, 0},
    {10, "Platform Designation", Kind::kString, 0, 0, 0},
    {11, "Image Source Sensor", Kind::kString, 0, 0, 0},
    {12, "Image Coordinate System", Kind::kString, 0, 0, 0},
    {13, "Sensor Latitude", Kind::kIntMap, 4, 0, 90},
    {14, "Sensor Longitude", Kind::kIntMap, 4, 0, 180},
    {15, "Sensor True Altitude", Kind::kUintMap, 2, -900, 19000},
    {16, "Sensor Horizontal Field of View", Kind::kUintMap, 2, 0, 180},
    {17, "Sensor Vertical Field of View", Kind::kUintMap, 2, 0, 180},
    {18, "Sensor Relative Azimuth Angle", Kind::kUintMap, 4, 0, 360},
    {19, "Sensor Relative Elevation Angle", Kind::kIntMap, 4, 0, 180},
    {20, "Sensor Relative Roll Angle", Kind::kUintMap, 4, 0, 360},
    {21, "Slant Range", Kind::kUintMap, 4, 0, 5000000},
    {22, "Target Width", Kind::kUintMap, 2, 0, 10000},
    {23, "Frame Center Latitude", Kind::kIntMap, 4, 0, 90},
    {24, "Frame Center Longitude", Kind::kIntMap, 4, 0, 180},
    {25, "Frame Center Elevation", Kind::kUintMap, 2, -900, 19000},
    {26, "Offset Corner Latitude Point 1", Kind::kIntMap, 2, 0, 0.075},
    {27, "Offset Corner Longitude Point 1", Kind::kIntMap, 2, 0, 0.075},
    {28, "Offset Corner Latitude Point 2", Kind::kIntMap, 2, 0, 0.075},
    {29, "Offset Corner Longitude Point 2", Kind::kIntMap, 2, 0, 0.075},
    {30, "Offset Corner Latitude Point 3", Kind::kIntMap, 2, 0, 0.075},
    {31, "Offset Corner Longitude Point 3", Kind::kIntMap, 2, 0, 0.075},
    {32, "Offset Corner Latitude Point 4", Kind::kIntMap, 2, 0, 0.075},
    {33, "Offset Corner Longitude Point 4", Kind::kIntMap, 2, 0, 0.075},
    {34, "Icing Detected", Kind::kEnum, 1, 0, 0},
    {35, "Wind Direction", Kind::kUintMap, 2, 0, 360},
    {36, "Wind Speed", Kind::kUintMap, 1, 0, 100},
    {37, "Static Pressure", Kind::kUintMap, 2, 0, 5000},
    {38, "Density Altitude", Kind::kUintMap, 2, -900, 19000},
    {39, "Outside Air Temperature", Kind::kInt, 1, 0, 0},
    {40, "Target Location Latitude", Kind::kIntMap, 4, 0, 90},
    {41, "Target Location Longitude", Kind::kIntMap, 4, 0, 180},
    {42, "Target Location Elevation", Kind::kUintMap, 2, -900, 19000},
    {43, "Target Track Gate Width", Kind::kUintMap, 1, 0, 510},
    {44, "Target Track Gate Height", Kind::kUintMap, 1, 0, 510},
    {45, "Target Error Estimate - CE90", Kind::kUintMap, 2, 0, 4095},
    {46, "Target Error Estimate - LE90", Kind::kUintMap, 2, 0, 4095},
    {47, "Generic Flag Data", Kind::kUint, 1, 0, 0},
    {48, "Security Local Set", Kind::kSt0102, 0, 0, 0},
    {49, "Differential Pressure", Kind::kUintMap, 2, 0, 5000},
    {50, "Platform Angle of Attack", Kind::kIntMap, 2, 0, 20},
    {51, "Platform Vertical Speed", Kind::kIntMap, 2, 0, 180},
    {52, "Platform Sideslip Angle", Kind::kIntMap, 2, 0, 20},
    {53, "Airfield Barometric Pressure", Kind::kUintMap, 2, 0, 5000},
    {54, "Airfield Elevation", Kind::kUintMap, 2, -900, 19000},
    {55, "Relative Humidity", Kind::kUintMap, 1, 0, 100},
    {56, "Platform Ground Speed", Kind::kUint, 1, 0, 0},
    {57, "Ground Range", Kind::kUintMap, 4, 0, 5000000},
    {58, "Platform Fuel Remaining", Kind::kUintMap, 2, 0, 10000},
    {59, "Platform Call Sign", Kind::kString, 0, 0, 0},
    {60, "Weapon Load", Kind::kUint, 2, 0, 0},
    {61, "Weapon Fired", Kind::kUint, 1, 0, 0},
    {62, "Laser PRF Code", Kind::kUint, 2, 0, 0},
    {63, "Sensor Field of View Name", Kind::kEnum, 1, 0, 0},
    {64, "Platform Magnetic Heading", Kind::kUintMap, 2, 0, 360},
    {65, "UAS Datalink LS Version Number", Kind::kUint, 1, 0, 0},
    {66, "Target Location Covariance Matrix", Kind::kBytes, 0, 0, 0},
    {67, "Alternate Platform Latitude", Kind::kIntMap, 4, 0, 90},
    {68, "Alternate Platform Longitude", Kind::kIntMap, 4, 0, 180},
    {69, "Alternate Platform Altitude", Kind::kUintMap, 2, -900, 19000},
    {70, "Alternate Platform Name", Kind::kString, 0, 0, 0},
    {71, "Alternate Platform Heading", Kind::kUintMap, 2, 0, 360},
    {72, "Event Start Time - UTC", Kind::kUint, 8, 0, 0},
    {73, "RVT Local Set", Kind::kBytes, 0, 0, 0},
    {74, "VMTI Local Set", Kind::kBytes, 0, 0, 0},
    {75, "Sensor Ellipsoid Height", Kind::kUintMap, 2, -900, 19000},
    {76, "Alternate Platform Ellipsoid Height", Kind::kUintMap, 2, -900, 19000},
    {77, "Operational Mode", Kind::kEnum, 1, 0, 0},
    {78, "Frame Center Height Above Ellipsoid", Kind::kUintMap, 2, -900, 19000},
    {79, "Sensor North Velocity", Kind::kIntMap, 2, 0, 327},
    {80, "Sensor East Velocity", Kind::kIntMap, 2, 0, 327},
    {81, "Image Horizon Pixel Pack", Kind::kBytes, 0, 0, 0},
    {82, "Corner Latitude Point 1 (Full)", Kind::kIntMap, 4, 0, 90},
    {83, "Corner Longitude Point 1 (Full)", Kind::kIntMap, 4, 0, 180},
    {84, "Corner Latitude Point 2 (Full)", Kind::kIntMap, 4, 0, 90},
    {85, "Corner Longitude Point 2 (Full)", Kind::kIntMap, 4, 0, 180},
    {86, "Corner Latitude Point 3 (Full)", Kind::kIntMap, 4, 0, 90},
    {87, "Corner Longitude Point 3 (Full)", Kind::kIntMap, 4, 0, 180},
    {88, "Corner Latitude Point 4 (Full)", Kind::kIntMap, 4, 0, 90},
    {89, "Corner Longitude Point 4 (Full)", Kind::kIntMap, 4, 0, 180},
    {90, "Platform Pitch Angle (Full)", Kind::kIntMap, 4, 0, 90},
    {91, "Platform Roll Angle (Full)", Kind::kIntMap, 4, 0, 90},
    {92, "Platform Angle of Attack (Full)", Kind::kIntMap, 4, 0, 90},
    {93, "Platform Sideslip Angle (Full)", Kind::kIntMap, 4, 0, 180},
    {94, "MIIS Core Identifier", Kind::kBytes, 0, 0, 0},
    {95, "SAR Motion Imagery Local Set", Kind::kBytes, 0, 0, 0},
    {96, "Target Width Extended", Kind::kImapb, 0, 0, 1500000},
    {97, "Range Image Local Set", Kind::kBytes, 0, 0, 0},
    {98, "Geo-Registration Local Set", Kind::kBytes, 0, 0, 0},
    {99, "Composite Imaging Local Set", Kind::kBytes, 0, 0, 0},
    {100, "Segment Local Set", Kind::kNested, 0, 0, 0},
    {101, "Amend Local Set", Kind::kNested, 0, 0, 0},
    {102, "SDCC-FLP", Kind::kBytes, 0, 0, 0},
    {103, "Density Altitude Extended", Kind::kImapb, 0, -900, 40000},
    {104, "Sensor Ellipsoid Height Extended", Kind::kImapb, 0, -900, 40000},
    {105, "Alternate Platform Ellipsoid Height Extended", Kind::kImapb, 0, -900, 40000},
    {106, "Stream Designator", Kind::kString, 0, 0, 0},
    {107, "Operational Base", Kind::kString, 0, 0, 0},
    {108, "Broadcast Source", Kind::kString, 0, 0, 0},
    {109, "Range To Recovery Location", Kind::kImapb, 0, 0, 21000},
    {110, "Time Airborne", Kind::kUint, 4, 0, 0},
    {111, "Propulsion Unit Speed", Kind::kUint, 4, 0, 0},
    {112, "Platform Course Angle", Kind::kImapb, 0, 0, 360},
    {113, "Altitude Above Ground Level", Kind::kImapb, 0, -900, 40000},
    {114, "Radar Altimeter", Kind::kImapb, 0, -900, 40000},
    {115, "Control Command", Kind::kBytes, 0, 0, 0},
    {116, "Control Command Verification List", Kind::kBytes, 0, 0, 0},
    {117, "Sensor Azimuth Rate", Kind::kImapb, 0, -1000, 1000},
    {118, "Sensor Elevation Rate", Kind::kImapb, 0, -1000, 1000},
    {119, "Sensor Roll Rate", Kind::kImapb, 0, -1000, 1000},
    {120, "On-board MI Storage Percent Full", Kind::kImapb, 0, 0, 100},
    {121, "Active Wavelength List", Kind::kBytes, 0, 0, 0},
    {122, "Country Codes", Kind::kBytes, 0, 0, 0},
    {123, "Number of NAVSATs in View", Kind::kUint, 1, 0, 0},
    {124, "Positioning Method Source", Kind::kUint, 1, 0, 0},
    {125, "Platform Status", Kind::kEnum, 1, 0, 0},
    {126, "Sensor Control Mode", Kind::kEnum, 1, 0, 0},
    {127, "Sensor Frame Rate Pack", Kind::kBytes, 0, 0, 0},
    {128, "Wavelengths List", Kind::kBytes, 0, 0, 0},
    {129, "Target ID", Kind::kString, 0, 0, 0},
    {130, "Airbase Locations", Kind::kBytes, 0, 0, 0},
    {131, "Take-off Time", Kind::kUint, 8, 0, 0},
    {132, "Transmission Frequency", Kind::kImapb, 0, 1, 99999},
    {133, "On-board MI Storage Capacity", Kind::kUint, 4, 0, 0},
    {134, "Zoom Percentage", Kind::kImapb, 0, 0, 100},
    {135, "Communications Method", Kind::kString, 0, 0, 0},
    {136, "Leap Seconds", Kind::kInt, 4, 0, 0},
    {137, "Correction Offset", Kind::kInt, 8, 0, 0},
    {138, "Payload List", Kind::kBytes, 0, 0, 0},
    {139, "Active Payloads", Kind::kBytes, 0, 0, 0},
    {140, "Weapons Stores", Kind::kBytes, 0, 0, 0},
    {141, "Waypoint List", Kind::kBytes, 0, 0, 0},
    {142, "View Domain", Kind::kBytes, 0, 0, 0},
    {143, "Metadata Substream ID", Kind::kBytes, 0, 0, 0},
};

const TagSpec* FindSpec(uint64_t tag) {
  if (tag == 0 || tag > 143) return nullptr;
  const auto* it = std::lower_bound(std::begin(kSpecs), std::end(kSpecs), tag,
                                    [](const TagSpec& s, uint64_t t) { return s.tag < t; });
  return (it != std::end(kSpecs) && it->tag == tag) ? it : nullptr;
}

constexpr int kMaxDepth = 3;

Item DecodeItem(uint64_t tag, ByteSpan v, ParseStats* stats, int depth) {
  Item item;
  item.tag = tag;
  const TagSpec* spec = FindSpec(tag);
  item.name = spec ? spec->name : "Unknown Tag";
  auto unparsed = [&](bool count) {
    item.parsed = false;
    item.value = nullptr;
    item.unparsed.assign(v.data, v.data + v.size);
    if (count) ++stats->bad_items;
    return item;
  };
  if (!spec) return unparsed(false);
  const size_t max_len = spec->length ? spec->length : 8;
  switch (spec->kind) {
    case Kind::kUint:
      if (v.size == 0 || v.size > max_len) return unparsed(true);
      item.value = ReadUintBE(v);
      break;
    case Kind::kInt:
      if (v.size == 0 || v.size > max_len) return unparsed(true);
      item.value = ReadIntBE(v);
      break;
    case Kind::kChecksum:
      if (v.size != 2) return unparsed(true);
      item.value = ReadUintBE(v);
      break;
    case Kind::kUintMap:
      if (v.size != spec->length) return unparsed(true);
      item.value = MapUnsigned(ReadUintBE(v), v.size, spec->a, spec->b);
      break;
    case Kind::kIntMap: {
      if (v.size != spec->length) return unparsed(true);
      const auto d = MapSigned(ReadIntBE(v), v.size, spec->b);
      item.value = d ? nlohmann::json(*d) : nlohmann::json();
      break;
    }
    case Kind::kImapb: {
      if (v.size == 0 || v.size > 8) return unparsed(true);
      const auto d = DecodeImapb(v, spec->a, spec->b);
      item.value = d ? nlohmann::json(*d) : nlohmann::json();
      break;
    }
    case Kind::kString: {
      auto s = Utf8String(v);
      if (!s) return unparsed(true);
      item.value = *s;
      break;
    }
    case Kind::kEnum: {
      if (v.size != 1) return unparsed(true);
      const uint64_t e = ReadUintBE(v);
      item.value = EnumJson(e, St0601EnumName(tag, e));
      break;
    }
    case Kind::kSt0102: {
      std::vector<Item> sub;
      if (!DecodeSt0102Items(v, &sub, stats)) return unparsed(true);
      item.value = ItemsJson(sub);
      break;
    }
    case Kind::kNested: {
      std::vector<Item> sub;
      if (depth >= kMaxDepth || !DecodeSt0601Items(v, &sub, stats, depth + 1)) return unparsed(true);
      item.value = ItemsJson(sub);
      break;
    }
    case Kind::kBytes:
      return unparsed(false);
  }
  return item;
}

}  // namespace

bool DecodeSt0601Items(ByteSpan set, std::vector<Item>* items, ParseStats* stats, int depth) {
  std::vector<RawLocalItem> raw;
  if (!SplitLocalSet(set, &raw)) return false;
  for (const auto& r : raw) items->push_back(DecodeItem(r.tag, r.value, stats, depth));
  return true;
}

bool DecodeSt0601Packet(ByteSpan whole, ByteSpan set, Packet* out, ParseStats* stats) {
  out->standard = Standard::kSt0601;
  out->name = "MISB ST0601 Local Set";
  std::vector<RawLocalItem> raw;
  if (!SplitLocalSet(set, &raw) || raw.empty()) {
    ++stats->malformed;
    return false;
  }
  // The checksum must be the last item (tag 1, length 2); it covers every byte before its own value.
  const RawLocalItem& last = raw.back();
  if (last.tag != kTagChecksum || last.value.size != 2 || whole.size < 2) {
    ++stats->bad_checksum;
    return false;
  }
  const uint16_t stated = static_cast<uint16_t>(ReadUintBE(last.value));
  if (St0601Checksum(whole.Sub(0, whole.size - 2)) != stated) {
    ++stats->bad_checksum;
    return false;
  }
  for (const auto& r : raw) out->items.push_back(DecodeItem(r.tag, r.value, stats, 0));
  return true;
}

std::string St0601TagName(uint64_t tag) {
  const TagSpec* s = FindSpec(tag);
  return s ? s->name : "Unknown Tag";
}

std::string St0601EnumName(uint64_t tag, uint64_t value) {
  static const std::vector<const char*> kIcing = {"Detector Off", "No Icing Detected", "Icing Detected"};
  static const std::vector<const char*> kFov = {"Ultranarrow",    "Narrow",         "Medium",
                                                "Wide",           "Ultrawide",      "Narrow Medium",
                                                "2x Ultranarrow", "4x Ultranarrow", "Continuous Zoom"};
  static const std::vector<const char*> kMode = {"Other", "Operational", "Training", "Exercise", "Maintenance", "Test"};
  static const std::vector<const char*> kStatus = {
      "Active",  "Pre-flight",       "Pre-flight Taxiing", "Run-up",        "Take-off",
      "Ingress", "Manual Operation", "Automated Orbit",    "Transitioning", "Egress",
      "Landing", "Landed Taxiing",   "Landed Parked"};
  static const std::vector<const char*> kControl = {
      "Off",         "Home Position",           "Uncontrolled",   "Manual Control",
      "Calibrating", "Auto - Holding Position", "Auto - Tracking"};
  const std::vector<const char*>* names = nullptr;
  switch (tag) {
    case 34:
      names = &kIcing;
      break;
    case 63:
      names = &kFov;
      break;
    case 77:
      names = &kMode;
      break;
    case 125:
      names = &kStatus;
      break;
    case 126:
      names = &kControl;
      break;
    default:
      return "";
  }
  return value < names->size() ? (*names)[value] : "";
}

}  // namespace fmv3d::telemetry::klv
