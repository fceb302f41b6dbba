#include "fmv3d/io/exif.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <vector>

namespace fmv3d::io {
namespace {

// Bounds-checked TIFF/EXIF IFD reader over one buffer.
class TiffReader {
 public:
  TiffReader(const unsigned char* d, size_t n) : d_(d), n_(n) {}
  bool Init() {
    if (n_ < 8) return false;
    if (d_[0] == 'I' && d_[1] == 'I')
      le_ = true;
    else if (d_[0] == 'M' && d_[1] == 'M')
      le_ = false;
    else
      return false;
    return U16(2) == 42;
  }
  uint32_t FirstIfd() const { return U32(4); }
  bool Ok(size_t off, size_t len) const { return off <= n_ && len <= n_ - off; }
  uint16_t U16(size_t o) const {
    if (!Ok(o, 2)) return 0;
    return le_ ? uint16_t(d_[o] | d_[o + 1] << 8) : uint16_t(d_[o] << 8 | d_[o + 1]);
  }
  uint32_t U32(size_t o) const {
    if (!Ok(o, 4)) return 0;
    return le_ ? uint32_t(d_[o]) | uint32_t(d_[o + 1]) << 8 | uint32_t(d_[o + 2]) << 16 | uint32_t(d_[o + 3]) << 24
               : uint32_t(d_[o]) << 24 | uint32_t(d_[o + 1]) << 16 | uint32_t(d_[o + 2]) << 8 | uint32_t(d_[o + 3]);
  }
  struct Entry {
    uint16_t tag, type;
    uint32_t count;
    size_t value_offset;  // where the value bytes are (inline or pointed to); all count values lie in bounds
  };
  // Calls fn(entry) for each well-formed entry of the IFD at `off` (entries whose values would lie outside
  // the buffer are skipped).
  template <typename Fn>
  void ForEach(uint32_t off, Fn fn) const {
    if (off < 8 || !Ok(off, 2)) return;
    const int n = U16(off);
    for (int i = 0; i < n && i < 1000; ++i) {
      const size_t e = off + 2 + 12 * size_t(i);
      if (!Ok(e, 12)) return;
      Entry en{U16(e), U16(e + 2), U32(e + 4), 0};
      const size_t unit = TypeSize(en.type);
      if (unit == 0) continue;
      const uint64_t bytes = uint64_t(unit) * en.count;
      en.value_offset = bytes <= 4 ? e + 8 : U32(e + 8);
      if (bytes > n_ || !Ok(en.value_offset, size_t(bytes))) continue;
      fn(en);
    }
  }
  std::string Ascii(const Entry& e) const {
    if (e.type != 2 && e.type != 7 && e.type != 1) return "";
    std::string s(reinterpret_cast<const char*>(d_ + e.value_offset), e.count);
    s.erase(std::find(s.begin(), s.end(), '\0'), s.end());
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.erase(s.begin());
    return s;
  }
  // The i-th value of a numeric entry, nullopt when i is out of range, the type is not numeric or a rational
  // has a zero denominator.
  std::optional<double> Number(const Entry& e, uint32_t i = 0) const {
    if (i >= e.count) return std::nullopt;
    const size_t o = e.value_offset + size_t(i) * TypeSize(e.type);
    switch (e.type) {
      case 1:
        return d_[o];
      case 3:
        return U16(o);
      case 4:
        return U32(o);
      case 6:
        return static_cast<int8_t>(d_[o]);
      case 8:
        return static_cast<int16_t>(U16(o));
      case 9:
        return static_cast<int32_t>(U32(o));
      case 5: {
        const uint32_t num = U32(o), den = U32(o + 4);
        if (den == 0) return std::nullopt;
        return double(num) / den;
      }
      case 10: {
        const int32_t num = static_cast<int32_t>(U32(o)), den = static_cast<int32_t>(U32(o + 4));
        if (den == 0) return std::nullopt;
        return double(num) / den;
      }
      default:
        return std::nullopt;
    }
  }
  double NumberOr0(const Entry& e) const { return Number(e).value_or(0); }

 private:
  static size_t TypeSize(uint16_t type) {
    static const size_t kSize[] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8};
    return type < 13 ? kSize[type] : 0;
  }
  const unsigned char* d_;
  size_t n_;
  bool le_ = true;
};

// v as an integer of type T, 0 when it is not finite or outside T's range (EXIF values are untrusted: a cast
// of an out-of-range double would be undefined behaviour).
template <typename T>
T ToInt(double v) {
  if (!std::isfinite(v) || v < static_cast<double>(std::numeric_limits<T>::min()) ||
      v > static_cast<double>(std::numeric_limits<T>::max()))
    return 0;
  return static_cast<T>(v);
}

// Days from 1970-01-01 of a proleptic Gregorian date (H. Hinnant's days_from_civil).
int64_t DaysFromCivil(int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m > 2 ? m - 3 : m + 9) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<int64_t>(doe) - 719468;
}

// "YYYY:MM:DD" → days since 1970, nullopt when malformed.
std::optional<int64_t> ParseDate(const std::string& s) {
  int y = 0, m = 0, d = 0;
  if (s.size() < 10 || std::sscanf(s.c_str(), "%4d:%2d:%2d", &y, &m, &d) != 3) return std::nullopt;
  if (y < 1900 || y > 2200 || m < 1 || m > 12 || d < 1 || d > 31) return std::nullopt;
  return DaysFromCivil(y, static_cast<unsigned>(m), static_cast<unsigned>(d));
}

void ReadGpsIfd(const TiffReader& r, uint32_t off, ExifGps* gps) {
  char lat_ref = 0, lon_ref = 0;
  int alt_ref = 0;
  std::optional<double> lat, lon, alt, hms[3];
  std::string date;
  auto dms = [&](const TiffReader::Entry& e) -> std::optional<double> {
    if (e.type != 5 || e.count < 1) return std::nullopt;  // RATIONAL[3]: degrees, minutes, seconds
    double v = 0, scale = 1;
    for (uint32_t i = 0; i < std::min<uint32_t>(e.count, 3); ++i, scale *= 60) {
      const auto x = r.Number(e, i);
      if (!x) return std::nullopt;
      v += *x / scale;
    }
    return v;
  };
  r.ForEach(off, [&](const TiffReader::Entry& e) {
    switch (e.tag) {
      case 0x0001:
        lat_ref = r.Ascii(e).empty() ? 0 : r.Ascii(e)[0];
        break;
      case 0x0002:
        lat = dms(e);
        break;
      case 0x0003:
        lon_ref = r.Ascii(e).empty() ? 0 : r.Ascii(e)[0];
        break;
      case 0x0004:
        lon = dms(e);
        break;
      case 0x0005:
        alt_ref = ToInt<int>(r.NumberOr0(e));
        break;
      case 0x0006:
        alt = r.Number(e);
        break;
      case 0x0007:
        for (uint32_t i = 0; i < 3; ++i) hms[i] = r.Number(e, i);
        break;
      case 0x0009:
        gps->status = r.Ascii(e).empty() ? 0 : r.Ascii(e)[0];
        break;
      case 0x000A:
        gps->measure_mode = r.Ascii(e).empty() ? 0 : r.Ascii(e)[0];
        break;
      case 0x000B:
        gps->dop = r.Number(e);
        break;
      case 0x0012:
        gps->map_datum = r.Ascii(e);
        break;
      case 0x001D:
        date = r.Ascii(e);
        break;
      case 0x001F:
        gps->horizontal_error = r.Number(e);
        break;
      default:
        break;
    }
  });
  if (lat) gps->latitude = (lat_ref == 'S' || lat_ref == 's') ? -*lat : *lat;
  if (lon) gps->longitude = (lon_ref == 'W' || lon_ref == 'w') ? -*lon : *lon;
  if (alt) gps->altitude = alt_ref == 1 ? -*alt : *alt;
  const auto days = ParseDate(date);
  if (days && hms[0] && hms[1] && hms[2])
    gps->utc_seconds = static_cast<double>(*days) * 86400.0 + *hms[0] * 3600 + *hms[1] * 60 + *hms[2];
}

constexpr char kXmpHeader[] = "http://ns.adobe.com/xap/1.0/";  // followed by a NUL in the APP1 segment
constexpr size_t kMaxXmp = 1 << 20;

}  // namespace

ExifInfo ParseTiffExif(const unsigned char* data, size_t size) {
  ExifInfo info;
  TiffReader r(data, size);
  if (!r.Init() || r.FirstIfd() < 8 || !r.Ok(r.FirstIfd(), 2)) {
    info.damaged = true;
    return info;
  }
  uint32_t exif_ifd = 0, gps_ifd = 0;
  r.ForEach(r.FirstIfd(), [&](const TiffReader::Entry& e) {
    if (e.tag == 0x010F) info.make = r.Ascii(e);
    if (e.tag == 0x0110) info.model = r.Ascii(e);
    if (e.tag == 0x8769) exif_ifd = ToInt<uint32_t>(r.NumberOr0(e));
    if (e.tag == 0x8825) gps_ifd = ToInt<uint32_t>(r.NumberOr0(e));
    if (e.tag == 0x920A) info.focal_mm = r.NumberOr0(e);                        // TIFF/EP puts it in IFD0
    if (e.tag == 0x02BC && (e.type == 1 || e.type == 7) && e.count <= kMaxXmp)  // XMLPacket (TIFF files)
      info.xmp.assign(reinterpret_cast<const char*>(data + e.value_offset), e.count);
  });
  double fp_res = 0;
  int fp_unit = 2;
  if (exif_ifd) {
    r.ForEach(exif_ifd, [&](const TiffReader::Entry& e) {
      if (e.tag == 0x920A) info.focal_mm = r.NumberOr0(e);
      if (e.tag == 0xA405) info.focal_35mm = r.NumberOr0(e);
      if (e.tag == 0xA20E) fp_res = r.NumberOr0(e);
      if (e.tag == 0xA210) fp_unit = ToInt<int>(r.NumberOr0(e));
      if (e.tag == 0xA002) info.pixel_width = ToInt<int>(r.NumberOr0(e));
      if (e.tag == 0x9003) info.datetime_original = r.Ascii(e);
    });
  }
  if (gps_ifd) ReadGpsIfd(r, gps_ifd, &info.gps);
  // FocalPlaneResolutionUnit: 2 inch, 3 cm, 4 mm, 5 µm.
  const double per_mm = fp_unit == 2 ? 1 / 25.4 : fp_unit == 3 ? 0.1 : fp_unit == 4 ? 1.0 : fp_unit == 5 ? 1000.0 : 0;
  info.focal_plane_x_res = fp_res * per_mm;
  if (!(info.focal_mm > 0 && info.focal_mm < 5000)) info.focal_mm = 0;
  if (!(info.focal_35mm > 0 && info.focal_35mm < 5000)) info.focal_35mm = 0;
  return info;
}

ExifInfo ParseImageMetadata(const unsigned char* data, size_t size) {
  if (size >= 4 && ((data[0] == 'I' && data[1] == 'I') || (data[0] == 'M' && data[1] == 'M')))
    return ParseTiffExif(data, size);
  ExifInfo info;
  if (size < 4 || data[0] != 0xFF || data[1] != 0xD8) return info;
  // JPEG: walk the marker segments up to the first scan; the first "Exif" and the first XMP APP1 count.
  size_t pos = 2;
  bool have_exif = false;
  std::string xmp;
  for (int guard = 0; guard < 256 && pos + 4 <= size; ++guard) {
    if (data[pos] != 0xFF) break;
    const int marker = data[pos + 1];
    if (marker == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0xDA || marker == 0xD9) break;
    const size_t len = size_t(data[pos + 2]) << 8 | data[pos + 3];
    if (len < 2 || len - 2 > size - (pos + 4)) break;
    const unsigned char* seg = data + pos + 4;
    const size_t n = len - 2;
    if (marker == 0xE1 && !have_exif && n > 6 && std::memcmp(seg, "Exif\0\0", 6) == 0) {
      info = ParseTiffExif(seg + 6, n - 6);
      have_exif = true;
    } else if (marker == 0xE1 && xmp.empty() && n > sizeof(kXmpHeader) &&
               std::memcmp(seg, kXmpHeader, sizeof(kXmpHeader)) == 0) {  // sizeof includes the NUL
      xmp.assign(reinterpret_cast<const char*>(seg + sizeof(kXmpHeader)), n - sizeof(kXmpHeader));
    }
    pos += 2 + len;
  }
  if (info.xmp.empty()) info.xmp = std::move(xmp);
  return info;
}

ExifInfo ReadExif(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  unsigned char head[2] = {0, 0};
  in.read(reinterpret_cast<char*>(head), 2);
  if (in.gcount() != 2) return {};
  std::vector<unsigned char> buf(head, head + 2);
  if (head[0] == 0xFF && head[1] == 0xD8) {
    // JPEG: the metadata segments before the first scan (each at most 64 KiB, at most 256 of them).
    for (int guard = 0; guard < 256; ++guard) {
      unsigned char m[4];
      if (!in.read(reinterpret_cast<char*>(m), 4) || m[0] != 0xFF || m[1] == 0xDA || m[1] == 0xD9) break;
      const size_t len = size_t(m[2]) << 8 | m[3];
      if (len < 2) break;
      const size_t at = buf.size();
      buf.insert(buf.end(), m, m + 4);
      buf.resize(at + 4 + len - 2);
      if (!in.read(reinterpret_cast<char*>(buf.data() + at + 4), static_cast<std::streamsize>(len - 2))) {
        buf.resize(at);
        break;
      }
    }
    return ParseImageMetadata(buf.data(), buf.size());
  }
  // TIFF: IFDs may sit anywhere in the file, so it is read whole up to a bound (64 MiB).
  std::vector<unsigned char> chunk(1 << 16);
  while (in && buf.size() < (size_t(1) << 26)) {
    in.read(reinterpret_cast<char*>(chunk.data()), static_cast<std::streamsize>(chunk.size()));
    buf.insert(buf.end(), chunk.begin(), chunk.begin() + in.gcount());
  }
  return ParseImageMetadata(buf.data(), buf.size());
}

}  // namespace fmv3d::io
