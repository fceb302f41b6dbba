#include "fmv3d/telemetry/gpmf_writer.h"

#include <cmath>
#include <cstdio>
#include <ctime>

#include "fmv3d/core/error.h"

namespace fmv3d::telemetry::gpmf {
namespace {

void PutBE(std::vector<uint8_t>* b, uint64_t v, size_t n) {
  for (size_t i = 0; i < n; ++i) b->push_back(static_cast<uint8_t>(v >> (8 * (n - 1 - i))));
}

// key, type, structure size, repeat, then the data padded to 4 bytes.
void Entry(std::vector<uint8_t>* out, const char* key, char type, size_t ssize, size_t repeat,
           const std::vector<uint8_t>& data) {
  if (ssize > 255 || repeat > 65535) throw Error("GPMF: entry " + std::string(key) + " is too large");
  out->insert(out->end(), key, key + 4);
  out->push_back(static_cast<uint8_t>(type));
  out->push_back(static_cast<uint8_t>(ssize));
  PutBE(out, repeat, 2);
  out->insert(out->end(), data.begin(), data.end());
  while (out->size() % 4) out->push_back(0);
}

void Text(std::vector<uint8_t>* out, const char* key, const std::string& s) {
  Entry(out, key, 'c', 1, s.size(), std::vector<uint8_t>(s.begin(), s.end()));
}

int64_t Fixed(double v, double scale, double limit, const char* what) {
  const double x = std::round(v * scale);
  if (!std::isfinite(x) || std::abs(x) > limit) throw Error(std::string("GPMF: ") + what + " out of range");
  return static_cast<int64_t>(x);
}

std::string Gpsu(double unix_seconds) {
  const std::time_t t = static_cast<std::time_t>(std::floor(unix_seconds));
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%02d%02d%02d%02d%02d%06.3f", tm.tm_year % 100, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour,
                tm.tm_min, tm.tm_sec + (unix_seconds - std::floor(unix_seconds)));
  return buf;
}

}  // namespace

std::vector<uint8_t> EncodePayload(const PayloadContent& c) {
  std::vector<uint8_t> devc;
  {
    std::vector<uint8_t> id;
    PutBE(&id, 1, 4);
    Entry(&devc, "DVID", 'L', 4, 1, id);
  }
  Text(&devc, "DVNM", c.device_name);
  if (!c.gps.empty()) {
    std::vector<uint8_t> strm, data;
    for (auto& f : c.gps) {
      if (!(std::abs(f.latitude) <= 90) || !(std::abs(f.longitude) <= 180)) throw Error("GPMF: position out of range");
      PutBE(&data, static_cast<uint32_t>(Fixed(f.latitude, 1e7, 2.1e9, "latitude")), 4);
      PutBE(&data, static_cast<uint32_t>(Fixed(f.longitude, 1e7, 2.1e9, "longitude")), 4);
      PutBE(&data, static_cast<uint32_t>(Fixed(f.altitude, 1000, 2.1e9, "altitude")), 4);
      PutBE(&data, static_cast<uint32_t>(Fixed(f.speed_2d, 1000, 2.1e9, "speed")), 4);
      PutBE(&data, static_cast<uint32_t>(Fixed(f.speed_3d, 100, 2.1e9, "speed")), 4);
      if (c.gps9) {
        const double days = std::floor(f.unix_seconds / 86400) - 10957;  // days since 2000-01-01
        PutBE(&data, static_cast<uint32_t>(Fixed(days, 1, 2.1e9, "date")), 4);
        PutBE(&data, static_cast<uint32_t>(Fixed(std::fmod(f.unix_seconds, 86400.0), 1000, 2.1e9, "time")), 4);
        PutBE(&data, static_cast<uint16_t>(Fixed(c.gps_dop, 100, 65535, "DOP")), 2);
        PutBE(&data, static_cast<uint16_t>(Fixed(c.gps_fix, 1, 65535, "fix")), 2);
      }
    }
    std::vector<uint8_t> scal;
    if (c.gps9) {
      Text(&strm, "STNM", "GPS (Lat., Long., Alt., 2D, 3D, days, secs, DOP, fix)");
      Text(&strm, "TYPE", "lllllllSS");
      for (uint32_t s : {10000000u, 10000000u, 1000u, 1000u, 100u, 1u, 1000u, 100u, 1u}) PutBE(&scal, s, 4);
      Entry(&strm, "SCAL", 'l', 4, 9, scal);
      Entry(&strm, "UNIT", 'c', 3, 9, {'d', 'e', 'g', 'd', 'e', 'g', 'm', 0, 0, 'm', '/', 's', 'm', '/',
                                       's', 'd', 0,   0,   's', 0,   0,   0, 0, 0,   0,   0,   0});
      Entry(&strm, "GPS9", '?', 32, c.gps.size(), data);
    } else {
      Text(&strm, "STNM", "GPS (Lat., Long., Alt., 2D speed, 3D speed)");
      Entry(&strm, "UNIT", 'c', 3, 5, {'d', 'e', 'g', 'd', 'e', 'g', 'm', 0, 0, 'm', '/', 's', 'm', '/', 's'});
      for (uint32_t s : {10000000u, 10000000u, 1000u, 1000u, 100u}) PutBE(&scal, s, 4);
      Entry(&strm, "SCAL", 'l', 4, 5, scal);
      std::vector<uint8_t> v;
      PutBE(&v, static_cast<uint32_t>(Fixed(c.gps_fix, 1, 65535, "fix")), 4);
      Entry(&strm, "GPSF", 'L', 4, 1, v);
      const std::string u = Gpsu(c.gps.front().unix_seconds);
      Entry(&strm, "GPSU", 'U', 16, 1, std::vector<uint8_t>(u.begin(), u.end()));
      v.clear();
      PutBE(&v, static_cast<uint16_t>(Fixed(c.gps_dop, 100, 65535, "DOP")), 2);
      Entry(&strm, "GPSP", 'S', 2, 1, v);
      Entry(&strm, "GPS5", 'l', 20, c.gps.size(), data);
    }
    Entry(&devc, "STRM", 0, 1, strm.size(), strm);
  }
  if (!c.orientation.empty()) {
    std::vector<uint8_t> strm, data, scal;
    Text(&strm, "STNM", "CameraOrientation");
    PutBE(&scal, 32767, 2);
    Entry(&strm, "SCAL", 's', 2, 1, scal);
    for (const auto& q : c.orientation)
      for (double v : q) PutBE(&data, static_cast<uint16_t>(Fixed(v, 32767, 32767, "quaternion")), 2);
    Entry(&strm, "CORI", 's', 8, c.orientation.size(), data);
    Entry(&devc, "STRM", 0, 1, strm.size(), strm);
  }
  std::vector<uint8_t> out;
  Entry(&out, "DEVC", 0, 1, devc.size(), devc);
  return out;
}

}  // namespace fmv3d::telemetry::gpmf
