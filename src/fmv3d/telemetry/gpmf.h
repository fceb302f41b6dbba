// GoPro GPMF (General Purpose Metadata Format), parsed from the published specification
// (github.com/gopro/gpmf-parser, README "GPMF Deeper Dive"): a stream of KLV-like entries, each
//   4-byte FourCC key | 1-byte type | 1-byte structure size | 2-byte repeat (big endian) | data, padded to 4 bytes
// where the data holds `repeat` samples of `structure size` bytes. Type 0 nests entries (DEVC per device,
// STRM per stream); within a STRM, "sticky" metadata (SCAL scale, TYPE of a complex '?' structure, UNIT/SIUN
// units, STNM name, GPSF fix, GPSP precision, GPSU time, GPSA altitude system, STMP timestamp) precede the
// samples they describe. All numbers are big endian.
//
// Untrusted bytes: nothing is read outside the payload; an entry whose size runs past its container, a
// structure size that is not a whole number of elements, a TYPE that does not add up to the structure size or
// nesting deeper than 8 levels is counted in ParseStats::malformed and skipped with what follows at its level.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::telemetry::gpmf {

// One data entry of a stream (e.g. GPS5, ACCL, GYRO, CORI, or a device's own key), decoded to numbers with
// its stream's SCAL applied (value / scale, one scale for all elements or one per element).
struct Stream {
  std::string device;               // DVNM of the enclosing DEVC ("" when absent)
  uint32_t device_id = 0;           // DVID (when numeric)
  std::string key;                  // the data's FourCC
  std::string name;                 // STNM
  std::vector<std::string> units;   // SIUN or UNIT: one per element, or one for all
  std::string type;                 // for complex ('?') data: its TYPE with arrays expanded, e.g. "lllllllSS"
  size_t elements = 0;              // numbers per sample
  std::vector<double> values;       // samples × elements (non-numeric elements, e.g. FourCC, are NaN)
  std::optional<double> gps_fix;    // GPSF: 0 no lock, 2 2D, 3 3D
  std::optional<double> gps_dop;    // GPSP / 100
  std::string gps_utc;              // GPSU "yymmddhhmmss.sss"
  std::string altitude_system;      // GPSA, e.g. "MSLV" (mean sea level) or "WGS8" (ellipsoid)
  std::optional<uint64_t> stmp_us;  // STMP, microseconds
  size_t samples() const { return elements ? values.size() / elements : 0; }
  double at(size_t sample, size_t element) const { return values[sample * elements + element]; }
};

struct ParseStats {
  size_t entries = 0;      // KLV entries read
  size_t malformed = 0;    // entries or containers skipped as malformed (see above)
  size_t unsupported = 0;  // data of a type we do not decode (strings, GUIDs, ...) in a sample position
};

// Every data entry of one payload (the bytes of one `gpmd` sample, or a raw .gpmf/.raw dump). Never throws.
std::vector<Stream> ParsePayload(const uint8_t* data, size_t size, ParseStats* stats = nullptr);

// Size in bytes of one element of a GPMF type character, 0 for an unknown type or '?' / nest.
size_t TypeSize(char type);

// Expands a TYPE string's array notation ("f[3]L" → "fffL"); nullopt when malformed or longer than `max`.
std::optional<std::string> ExpandType(const std::string& type, size_t max = 1024);

}  // namespace fmv3d::telemetry::gpmf
