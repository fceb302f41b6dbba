#include "fmv3d/io/exif_writer.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "fmv3d/core/error.h"

namespace fmv3d::io {
namespace {

enum Type : uint16_t { kByte = 1, kAscii = 2, kShort = 3, kLong = 4, kRational = 5 };

struct Field {
  uint16_t tag, type;
  uint32_t count;
  std::vector<uint8_t> data;  // little endian
};

void Put16(std::vector<uint8_t>* b, uint16_t v) {
  b->push_back(v & 0xFF);
  b->push_back(v >> 8);
}
void Put32(std::vector<uint8_t>* b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b->push_back((v >> (8 * i)) & 0xFF);
}

Field Ascii(uint16_t tag, const std::string& s) {
  Field f{tag, kAscii, static_cast<uint32_t>(s.size() + 1), std::vector<uint8_t>(s.begin(), s.end())};
  f.data.push_back(0);
  return f;
}
Field Short(uint16_t tag, uint16_t v) {
  Field f{tag, kShort, 1, {}};
  Put16(&f.data, v);
  return f;
}
Field Long(uint16_t tag, uint32_t v) {
  Field f{tag, kLong, 1, {}};
  Put32(&f.data, v);
  return f;
}
Field Byte(uint16_t tag, std::vector<uint8_t> v) { return {tag, kByte, static_cast<uint32_t>(v.size()), std::move(v)}; }
// Unsigned rationals num/den.
Field Rationals(uint16_t tag, const std::vector<std::pair<uint32_t, uint32_t>>& r) {
  Field f{tag, kRational, static_cast<uint32_t>(r.size()), {}};
  for (const auto& [n, d] : r) {
    Put32(&f.data, n);
    Put32(&f.data, d);
  }
  return f;
}
std::pair<uint32_t, uint32_t> Rational(double v, uint32_t den) {
  if (!std::isfinite(v) || v < 0 || v * den > 4294967295.0)
    throw Error("EXIF: value " + std::to_string(v) + " cannot be written as a rational");
  return {static_cast<uint32_t>(std::llround(v * den)), den};
}
// |angle| as degrees, minutes, seconds (1e-4 s).
Field Dms(uint16_t tag, double angle) {
  const uint64_t total = static_cast<uint64_t>(std::llround(std::abs(angle) * 3600.0 * 1e4));
  const uint32_t deg = static_cast<uint32_t>(total / 36000000), min = static_cast<uint32_t>(total / 600000 % 60);
  const uint32_t sec = static_cast<uint32_t>(total % 600000);
  return Rationals(tag, {{deg, 1}, {min, 1}, {sec, 10000}});
}

// Bytes an IFD with these fields takes, its out-of-line values included (each padded to an even size).
size_t IfdSize(const std::vector<Field>& fields) {
  size_t n = 2 + 12 * fields.size() + 4;
  for (const Field& f : fields)
    if (f.data.size() > 4) n += f.data.size() + (f.data.size() & 1);
  return n;
}

// Appends the IFD (at offset out->size()) and its values; the next-IFD link is 0.
void WriteIfd(std::vector<Field> fields, std::vector<uint8_t>* out) {
  std::sort(fields.begin(), fields.end(), [](const Field& a, const Field& b) { return a.tag < b.tag; });
  const size_t start = out->size();
  size_t data_at = start + 2 + 12 * fields.size() + 4;
  std::vector<uint8_t> data;
  Put16(out, static_cast<uint16_t>(fields.size()));
  for (const Field& f : fields) {
    Put16(out, f.tag);
    Put16(out, f.type);
    Put32(out, f.count);
    if (f.data.size() <= 4) {
      std::vector<uint8_t> v = f.data;
      v.resize(4, 0);
      out->insert(out->end(), v.begin(), v.end());
    } else {
      Put32(out, static_cast<uint32_t>(data_at + data.size()));
      data.insert(data.end(), f.data.begin(), f.data.end());
      if (f.data.size() & 1) data.push_back(0);
    }
  }
  Put32(out, 0);
  out->insert(out->end(), data.begin(), data.end());
}

std::string FormatDate(double utc_seconds, bool date) {
  const int64_t secs = static_cast<int64_t>(std::floor(utc_seconds));
  int64_t z = secs / 86400 + 719468;  // civil_from_days (H. Hinnant)
  const int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const unsigned doe = static_cast<unsigned>(z - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const unsigned doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy + 2) / 153;
  const unsigned d = doy - (153 * mp + 2) / 5 + 1, m = mp < 10 ? mp + 3 : mp - 9;
  const int64_t y = static_cast<int64_t>(yoe) + era * 400 + (m <= 2);
  char buf[32];
  if (date)
    std::snprintf(buf, sizeof buf, "%04lld:%02u:%02u", static_cast<long long>(y), m, d);
  else
    std::snprintf(buf, sizeof buf, "%04lld:%02u:%02u %02lld:%02lld:%02lld", static_cast<long long>(y), m, d,
                  static_cast<long long>(secs % 86400 / 3600), static_cast<long long>(secs % 3600 / 60),
                  static_cast<long long>(secs % 60));
  return buf;
}

}  // namespace

std::vector<uint8_t> EncodeTiffExif(const ExifInfo& e) {
  std::vector<Field> ifd0, exif, gps;
  if (!e.make.empty()) ifd0.push_back(Ascii(0x010F, e.make));
  if (!e.model.empty()) ifd0.push_back(Ascii(0x0110, e.model));
  if (!e.datetime_original.empty()) exif.push_back(Ascii(0x9003, e.datetime_original));
  if (e.focal_mm > 0) exif.push_back(Rationals(0x920A, {Rational(e.focal_mm, 1000)}));
  if (e.focal_35mm > 0) exif.push_back(Short(0xA405, static_cast<uint16_t>(std::lround(e.focal_35mm))));
  if (e.focal_plane_x_res > 0) {
    // In pixels per inch (unit 2), the unit most cameras write; the reader converts it back to pixels per mm.
    const auto per_inch = Rational(e.focal_plane_x_res * 25.4, 1000);
    exif.push_back(Rationals(0xA20E, {per_inch}));
    exif.push_back(Rationals(0xA20F, {per_inch}));
    exif.push_back(Short(0xA210, 2));
  }
  if (e.pixel_width > 0) exif.push_back(Long(0xA002, static_cast<uint32_t>(e.pixel_width)));
  const ExifGps& g = e.gps;
  if (g.present() || g.dop || g.utc_seconds) {
    gps.push_back(Byte(0x0000, {2, 3, 0, 0}));
    if (g.latitude) {
      if (!(std::abs(*g.latitude) <= 90)) throw Error("EXIF: latitude out of range");
      gps.push_back(Ascii(0x0001, *g.latitude < 0 ? "S" : "N"));
      gps.push_back(Dms(0x0002, *g.latitude));
    }
    if (g.longitude) {
      if (!(std::abs(*g.longitude) <= 180)) throw Error("EXIF: longitude out of range");
      gps.push_back(Ascii(0x0003, *g.longitude < 0 ? "W" : "E"));
      gps.push_back(Dms(0x0004, *g.longitude));
    }
    if (g.altitude) {
      gps.push_back(Byte(0x0005, {static_cast<uint8_t>(*g.altitude < 0 ? 1 : 0)}));
      gps.push_back(Rationals(0x0006, {Rational(std::abs(*g.altitude), 1000)}));
    }
    if (g.utc_seconds) {
      const double day = std::fmod(*g.utc_seconds, 86400.0);
      gps.push_back(Rationals(0x0007, {{static_cast<uint32_t>(day / 3600), 1},
                                       {static_cast<uint32_t>(std::fmod(day, 3600.0) / 60), 1},
                                       Rational(std::fmod(day, 60.0), 1000)}));
      gps.push_back(Ascii(0x001D, FormatDate(*g.utc_seconds, true)));
    }
    if (g.status) gps.push_back(Ascii(0x0009, std::string(1, g.status)));
    if (g.measure_mode) gps.push_back(Ascii(0x000A, std::string(1, g.measure_mode)));
    if (g.dop) gps.push_back(Rationals(0x000B, {Rational(*g.dop, 100)}));
    if (!g.map_datum.empty()) gps.push_back(Ascii(0x0012, g.map_datum));
    if (g.horizontal_error) gps.push_back(Rationals(0x001F, {Rational(*g.horizontal_error, 100)}));
  }
  // Layout: header, IFD0, EXIF IFD, GPS IFD (the pointers' sizes are known before their values).
  if (!exif.empty()) ifd0.push_back(Long(0x8769, 0));
  if (!gps.empty()) ifd0.push_back(Long(0x8825, 0));
  const size_t exif_at = 8 + IfdSize(ifd0), gps_at = exif_at + (exif.empty() ? 0 : IfdSize(exif));
  for (Field& f : ifd0) {
    if (f.tag == 0x8769) f = Long(0x8769, static_cast<uint32_t>(exif_at));
    if (f.tag == 0x8825) f = Long(0x8825, static_cast<uint32_t>(gps_at));
  }
  std::vector<uint8_t> out = {'I', 'I', 42, 0};
  Put32(&out, 8);
  WriteIfd(ifd0, &out);
  if (!exif.empty()) WriteIfd(exif, &out);
  if (!gps.empty()) WriteIfd(gps, &out);
  return out;
}

std::vector<uint8_t> InsertJpegMetadata(const std::vector<uint8_t>& jpeg, const std::vector<uint8_t>& tiff,
                                        const std::string& xmp) {
  if (jpeg.size() < 4 || jpeg[0] != 0xFF || jpeg[1] != 0xD8) throw Error("EXIF: not a JPEG stream");
  std::vector<uint8_t> out = {0xFF, 0xD8};
  auto segment = [&](const char* header, size_t header_size, const uint8_t* body, size_t n) {
    const size_t len = 2 + header_size + n;
    if (len > 65535) throw Error("EXIF: metadata segment of " + std::to_string(len) + " bytes exceeds 64 KiB");
    out.insert(out.end(), {0xFF, 0xE1, static_cast<uint8_t>(len >> 8), static_cast<uint8_t>(len & 0xFF)});
    out.insert(out.end(), header, header + header_size);
    out.insert(out.end(), body, body + n);
  };
  if (!tiff.empty()) segment("Exif\0\0", 6, tiff.data(), tiff.size());
  if (!xmp.empty()) {
    static const char kXmp[] = "http://ns.adobe.com/xap/1.0/";
    segment(kXmp, sizeof(kXmp), reinterpret_cast<const uint8_t*>(xmp.data()), xmp.size());
  }
  out.insert(out.end(), jpeg.begin() + 2, jpeg.end());
  return out;
}

}  // namespace fmv3d::io
