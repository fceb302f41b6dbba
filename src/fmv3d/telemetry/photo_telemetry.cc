#include "fmv3d/telemetry/photo_telemetry.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/attitude.h"

namespace fmv3d::telemetry {
namespace {

constexpr char kPrefix[] = "drone-dji:";
constexpr size_t kMaxValue = 64;  // longer values are not numbers we read

bool IsNameChar(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }

// Every drone-dji:Name → value (the first occurrence of each name).
std::map<std::string, std::string> DjiFields(const std::string& x) {
  std::map<std::string, std::string> out;
  const size_t plen = sizeof(kPrefix) - 1;
  for (size_t pos = x.find(kPrefix); pos != std::string::npos; pos = x.find(kPrefix, pos + 1)) {
    // Skip closing tags (</drone-dji:Name>) and namespace declarations (xmlns:drone-dji=...).
    if (pos > 0 && (x[pos - 1] == '/' || x[pos - 1] == ':')) continue;
    size_t i = pos + plen, name_end = i;
    while (name_end < x.size() && name_end - i < 64 && IsNameChar(x[name_end])) ++name_end;
    if (name_end == i) continue;
    const std::string name = x.substr(i, name_end - i);
    i = name_end;
    while (i < x.size() && std::isspace(static_cast<unsigned char>(x[i]))) ++i;
    if (i >= x.size()) break;
    size_t vbeg, vend;
    if (x[i] == '=') {  // attribute: Name="value" or Name='value'
      ++i;
      while (i < x.size() && std::isspace(static_cast<unsigned char>(x[i]))) ++i;
      if (i >= x.size() || (x[i] != '"' && x[i] != '\'')) continue;
      vbeg = i + 1;
      vend = x.find(x[i], vbeg);
    } else if (x[i] == '>') {  // element: <drone-dji:Name>value</drone-dji:Name>
      vbeg = i + 1;
      vend = x.find('<', vbeg);
    } else {
      continue;
    }
    if (vend == std::string::npos) break;
    if (!out.count(name)) out[name] = x.substr(vbeg, std::min(vend - vbeg, kMaxValue + 1));
  }
  return out;
}

// A finite number spanning the whole (trimmed) text, else nullopt.
std::optional<double> ToNumber(const std::string& v) {
  size_t b = 0, e = v.size();
  while (b < e && std::isspace(static_cast<unsigned char>(v[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(v[e - 1]))) --e;
  if (b == e || e - b > kMaxValue) return std::nullopt;
  const std::string t = v.substr(b, e - b);
  char* end = nullptr;
  const double d = std::strtod(t.c_str(), &end);
  if (end != t.c_str() + t.size() || !std::isfinite(d)) return std::nullopt;
  return d;
}

const std::pair<const char*, std::optional<double> DjiXmp::*> kFieldMap[] = {
    {"GimbalYawDegree", &DjiXmp::gimbal_yaw},
    {"GimbalPitchDegree", &DjiXmp::gimbal_pitch},
    {"GimbalRollDegree", &DjiXmp::gimbal_roll},
    {"FlightYawDegree", &DjiXmp::flight_yaw},
    {"FlightPitchDegree", &DjiXmp::flight_pitch},
    {"FlightRollDegree", &DjiXmp::flight_roll},
    {"RelativeAltitude", &DjiXmp::relative_altitude},
    {"AbsoluteAltitude", &DjiXmp::absolute_altitude},
    {"GpsLatitude", &DjiXmp::latitude},
    {"GpsLongitude", &DjiXmp::longitude},
    {"GpsLongtitude", &DjiXmp::longitude},
    {"RtkFlag", &DjiXmp::rtk_flag},
    {"RtkStdLon", &DjiXmp::rtk_std_lon},
    {"RtkStdLat", &DjiXmp::rtk_std_lat},
    {"RtkStdHgt", &DjiXmp::rtk_std_hgt},
};

}  // namespace

DjiXmp ParseDjiXmp(const std::string& xmp) {
  DjiXmp d;
  const auto fields = DjiFields(xmp);
  d.fields = fields.size();
  for (const auto& [name, member] : kFieldMap) {
    const auto it = fields.find(name);
    if (it == fields.end() || d.*member) continue;
    if (auto v = ToNumber(it->second))
      d.*member = *v;
    else
      ++d.malformed;
  }
  return d;
}

std::string EncodeDjiXmp(const DjiXmp& d) {
  std::string attrs;
  for (const auto& [name, member] : kFieldMap) {
    if (!(d.*member) || std::strcmp(name, "GpsLongtitude") == 0) continue;
    char buf[96];
    std::snprintf(buf, sizeof buf, "\n    drone-dji:%s=\"%+.8f\"", name, *(d.*member));
    attrs += buf;
  }
  return "<?xpacket begin=\"\xEF\xBB\xBF\" id=\"W5M0MpCehiHzreSzNTczkc9d\"?>\n"
         "<x:xmpmeta xmlns:x=\"adobe:ns:meta/\">\n <rdf:RDF "
         "xmlns:rdf=\"http://www.w3.org/1999/02/22-rdf-syntax-ns#\">\n"
         "  <rdf:Description rdf:about=\"\" xmlns:drone-dji=\"http://www.dji.com/drone-dji/1.0/\"" +
         attrs + ">\n  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>\n<?xpacket end=\"w\"?>";
}

AltitudeDatum ParseAltitudeDatum(const std::string& s) {
  if (s == "auto") return AltitudeDatum::kAuto;
  if (s == "msl") return AltitudeDatum::kMsl;
  if (s == "ellipsoid") return AltitudeDatum::kEllipsoid;
  throw Error("altitude datum \"" + s + "\": expected auto, msl or ellipsoid");
}

PhotoTelemetry TelemetryFromPhoto(const io::ExifInfo& exif, const PhotoTelemetryOptions& o) {
  PhotoTelemetry out;
  out.dji = ParseDjiXmp(exif.xmp);
  const DjiXmp& x = out.dji;
  const io::ExifGps& g = exif.gps;
  TelemetrySample s;
  s.time = 0;
  s.source = x.fields ? "EXIF+DJI-XMP" : "EXIF";
  if (g.latitude && g.longitude) {
    s.sensor_latitude = g.latitude;
    s.sensor_longitude = g.longitude;
  } else if (x.latitude && x.longitude) {
    s.sensor_latitude = x.latitude;
    s.sensor_longitude = x.longitude;
  }
  const std::optional<double> alt = x.absolute_altitude ? x.absolute_altitude : g.altitude;
  if (alt) {
    if (o.altitude_datum == AltitudeDatum::kEllipsoid)
      s.sensor_altitude_hae = alt;
    else
      s.sensor_altitude_msl = alt;  // kAuto: EXIF's definition and DJI's documentation (see the header)
  }
  s.sensor_relative_altitude = x.relative_altitude;
  s.gimbal_yaw = x.gimbal_yaw;
  s.gimbal_pitch = x.gimbal_pitch;
  s.gimbal_roll = x.gimbal_roll;
  s.platform_heading = x.flight_yaw ? std::optional<double>(Wrap360(*x.flight_yaw)) : std::nullopt;
  s.platform_pitch = x.flight_pitch;
  s.platform_roll = x.flight_roll;
  if (x.gimbal_yaw && x.gimbal_pitch && x.gimbal_roll && x.flight_yaw && x.flight_pitch && x.flight_roll) {
    const St0601Attitude a =
        St0601FromCameraToEnu(CameraToEnuFromGimbal(*x.gimbal_yaw, *x.gimbal_pitch, *x.gimbal_roll), *x.flight_yaw,
                              *x.flight_pitch, *x.flight_roll);
    s.sensor_relative_azimuth = a.sensor_relative_azimuth;
    s.sensor_relative_elevation = a.sensor_relative_elevation;
    s.sensor_relative_roll = a.sensor_relative_roll;
  }
  s.gps_dop = g.dop;
  if (g.measure_mode == '2' || g.measure_mode == '3') s.gps_fix = g.measure_mode - '0';
  if (g.status == 'V') s.gps_fix = 0;
  s.horizontal_accuracy = g.horizontal_error;
  // DJI writes the RTK standard deviations even without an RTK solution (then often 0): only a solution's count.
  if (x.rtk_flag && *x.rtk_flag > 0 && x.rtk_std_lon && x.rtk_std_lat && *x.rtk_std_lon > 0 && *x.rtk_std_lat > 0)
    s.horizontal_accuracy = std::max(*x.rtk_std_lon, *x.rtk_std_lat);
  if (x.rtk_flag && *x.rtk_flag > 0 && x.rtk_std_hgt && *x.rtk_std_hgt > 0) s.vertical_accuracy = x.rtk_std_hgt;
  s.rtk_flag = x.rtk_flag;
  if (g.utc_seconds && *g.utc_seconds > 0 && *g.utc_seconds < 1e10)
    s.unix_time_us = static_cast<uint64_t>(std::llround(*g.utc_seconds * 1e6));
  out.rejection = ScreenFix(s, o.fix);
  if (out.rejection == FixRejection::kNone) out.sample = std::move(s);
  return out;
}

}  // namespace fmv3d::telemetry
