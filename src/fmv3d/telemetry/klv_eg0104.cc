#include "fmv3d/telemetry/klv_eg0104.h"

#include "fmv3d/telemetry/klv_decode_util.h"
#include "fmv3d/telemetry/klv_st0102.h"

namespace fmv3d::telemetry::klv {

const UlKey kEg0104Key = {0x06, 0x0E, 0x2B, 0x34, 0x02, 0x01, 0x01, 0x01,
                          0x0E, 0x01, 0x01, 0x02, 0x01, 0x01, 0x00, 0x00};

namespace {

enum class Kind { kFloat4, kFloat, kDouble, kString, kUint64, kSecurity };

struct Spec {
  Eg0104Field field;
  uint64_t hi, lo;  // the key as two big-endian halves
  Kind kind;
  const char* name;
};

// EG 0104.5 / ST 0601.12 Appendix (the last table that lists the 0104 keys).
const Spec kSpecs[] = {
    {Eg0104Field::kUserDefinedTimestamp, 0x060E2B3401010101, 0x0702010101050000, Kind::kUint64,
     "User Defined Timestamp"},
    {Eg0104Field::kEpisodeNumber, 0x060E2B3401010101, 0x0105050000000000, Kind::kString, "Episode Number"},
    {Eg0104Field::kPlatformHeading, 0x060E2B3401010107, 0x0701100106000000, Kind::kFloat4, "Platform Heading Angle"},
    {Eg0104Field::kPlatformPitch, 0x060E2B3401010107, 0x0701100105000000, Kind::kFloat4, "Platform Pitch Angle"},
    {Eg0104Field::kPlatformRoll, 0x060E2B3401010107, 0x0701100104000000, Kind::kFloat4, "Platform Roll Angle"},
    {Eg0104Field::kDeviceDesignation, 0x060E2B3401010101, 0x0101200100000000, Kind::kString, "Device Designation"},
    {Eg0104Field::kImageSourceDevice, 0x060E2B3401010101, 0x0420010201010000, Kind::kString, "Image Source Device"},
    {Eg0104Field::kImageCoordinateSystem, 0x060E2B3401010101, 0x0701010100000000, Kind::kString,
     "Image Coordinate System"},
    {Eg0104Field::kDeviceLatitude, 0x060E2B3401010103, 0x0701020102040200, Kind::kDouble, "Device Latitude"},
    {Eg0104Field::kDeviceLongitude, 0x060E2B3401010103, 0x0701020102060200, Kind::kDouble, "Device Longitude"},
    {Eg0104Field::kDeviceAltitude, 0x060E2B3401010101, 0x0701020102020000, Kind::kFloat, "Device Altitude"},
    {Eg0104Field::kHorizontalFov, 0x060E2B3401010102, 0x0420020101080000, Kind::kFloat4, "Horizontal Field of View"},
    {Eg0104Field::kVerticalFov, 0x060E2B3401010107, 0x04200201010A0100, Kind::kFloat4, "Vertical Field of View"},
    {Eg0104Field::kSlantRange, 0x060E2B3401010101, 0x0701080101000000, Kind::kFloat, "Slant Range"},
    {Eg0104Field::kTargetWidth, 0x060E2B3401010101, 0x0701090201000000, Kind::kFloat, "Target Width"},
    {Eg0104Field::kFrameCenterLatitude, 0x060E2B3401010101, 0x0701020103020000, Kind::kDouble, "Frame Center Latitude"},
    {Eg0104Field::kFrameCenterLongitude, 0x060E2B3401010101, 0x0701020103040000, Kind::kDouble,
     "Frame Center Longitude"},
    {Eg0104Field::kFrameCenterElevation, 0x060E2B340101010A, 0x0701020103160000, Kind::kFloat,
     "Frame Center Elevation"},
    {Eg0104Field::kCornerLatitude1, 0x060E2B3401010103, 0x0701020103070100, Kind::kDouble, "Corner Latitude Point 1"},
    {Eg0104Field::kCornerLatitude2, 0x060E2B3401010103, 0x0701020103080100, Kind::kDouble, "Corner Latitude Point 2"},
    {Eg0104Field::kCornerLatitude3, 0x060E2B3401010103, 0x0701020103090100, Kind::kDouble, "Corner Latitude Point 3"},
    {Eg0104Field::kCornerLatitude4, 0x060E2B3401010103, 0x07010201030A0100, Kind::kDouble, "Corner Latitude Point 4"},
    {Eg0104Field::kCornerLongitude1, 0x060E2B3401010103, 0x07010201030B0100, Kind::kDouble, "Corner Longitude Point 1"},
    {Eg0104Field::kCornerLongitude2, 0x060E2B3401010103, 0x07010201030C0100, Kind::kDouble, "Corner Longitude Point 2"},
    {Eg0104Field::kCornerLongitude3, 0x060E2B3401010103, 0x07010201030D0100, Kind::kDouble, "Corner Longitude Point 3"},
    {Eg0104Field::kCornerLongitude4, 0x060E2B3401010103, 0x07010201030E0100, Kind::kDouble, "Corner Longitude Point 4"},
    {Eg0104Field::kSecurityLocalSet, 0x060E2B3402030101, 0x0E01030302000000, Kind::kSecurity, "Security Local Set"},
    {Eg0104Field::kStartDatetime, 0x060E2B3401010101, 0x0702010201010000, Kind::kString, "Start Datetime"},
    {Eg0104Field::kEventStartDatetime, 0x060E2B3401010101, 0x0702010207010000, Kind::kString, "Event Start Datetime"},
    {Eg0104Field::kSensorRollAngle, 0x060E2B3401010101, 0x0701100101000000, Kind::kFloat4, "Sensor Roll Angle"},
    {Eg0104Field::kAngleToNorth, 0x060E2B3401010101, 0x0701100102000000, Kind::kFloat4, "Angle to North"},
    {Eg0104Field::kObliquityAngle, 0x060E2B3401010101, 0x0701100103000000, Kind::kFloat4, "Obliquity Angle"},
};

UlKey MakeKey(uint64_t hi, uint64_t lo) {
  UlKey k{};
  for (int i = 0; i < 8; ++i) {
    k[i] = static_cast<uint8_t>(hi >> (56 - 8 * i));
    k[8 + i] = static_cast<uint8_t>(lo >> (56 - 8 * i));
  }
  return k;
}

const Spec* FindSpec(const UlKey& key) {
  for (const auto& s : kSpecs)
    if (UlEqualIgnoringVersion(key, MakeKey(s.hi, s.lo))) return &s;
  return nullptr;
}

}  // namespace

Eg0104Field Eg0104FieldOf(const UlKey& key) {
  const Spec* s = FindSpec(key);
  return s ? s->field : Eg0104Field::kUnknown;
}

std::string Eg0104KeyName(const UlKey& key) {
  const Spec* s = FindSpec(key);
  return s ? s->name : "Unknown Key";
}

UlKey Eg0104KeyOf(Eg0104Field f) {
  for (const auto& s : kSpecs)
    if (s.field == f) return MakeKey(s.hi, s.lo);
  return UlKey{};
}

bool DecodeEg0104Packet(ByteSpan set, Packet* out, ParseStats* stats) {
  out->standard = Standard::kEg0104;
  out->name = "MISB ST0104 Universal Set";
  Reader r(set);
  std::vector<Item> items;
  while (!r.empty()) {
    ByteSpan key_bytes, v;
    uint64_t len = 0;
    if (!r.ReadSpan(16, &key_bytes) || !r.ReadBerLength(&len) || len > r.remaining() ||
        !r.ReadSpan(static_cast<size_t>(len), &v)) {
      ++stats->malformed;
      return false;
    }
    Item item;
    UlKey key;
    std::copy(key_bytes.data, key_bytes.data + 16, key.begin());
    item.key = key;
    const Spec* spec = FindSpec(key);
    item.name = spec ? spec->name : "Unknown Key";
    bool ok = spec != nullptr;
    if (spec) {
      switch (spec->kind) {
        case Kind::kFloat4:
        case Kind::kFloat:
        case Kind::kDouble: {
          const bool len_ok = spec->kind == Kind::kFloat4   ? v.size == 4
                              : spec->kind == Kind::kDouble ? v.size == 8
                                                            : (v.size == 4 || v.size == 8);
          const auto d = len_ok ? ReadFloatBE(v) : std::nullopt;
          ok = d.has_value();
          if (ok) item.value = *d;  // NaN/inf are written as null by the JSON writer
          break;
        }
        case Kind::kString: {
          const auto s = Utf8String(v);
          ok = s.has_value();
          if (ok) item.value = *s;
          break;
        }
        case Kind::kUint64:
          ok = v.size >= 1 && v.size <= 8;
          if (ok) item.value = ReadUintBE(v);
          break;
        case Kind::kSecurity: {
          // The nested security set is itself a KLV triplet or a bare local set; take the bare form.
          std::vector<Item> sub;
          ok = DecodeSt0102Items(v, &sub, stats);
          if (ok) item.value = ItemsJson(sub);
          break;
        }
      }
      if (!ok) ++stats->bad_items;
    }
    if (!ok) {
      item.parsed = false;
      item.value = nullptr;
      item.unparsed.assign(v.data, v.data + v.size);
    }
    items.push_back(std::move(item));
  }
  out->items = std::move(items);
  return true;
}

}  // namespace fmv3d::telemetry::klv
