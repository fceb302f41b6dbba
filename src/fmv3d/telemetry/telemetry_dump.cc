#include "fmv3d/telemetry/telemetry_dump.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <iterator>

#include "fmv3d/core/error.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/telemetry/dji_srt.h"
#include "fmv3d/telemetry/gpmf_telemetry.h"

namespace fmv3d::telemetry {
namespace {

std::string LowerExt(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

template <typename T>
void Put(nlohmann::json* j, const char* key, const std::optional<T>& v) {
  if (v) (*j)[key] = *v;
}

nlohmann::json Samples(const std::vector<TelemetrySample>& samples) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& s : samples) a.push_back(ToJson(s));
  return a;
}

nlohmann::json FixesJson(const FixCounts& c) {
  nlohmann::json dropped = nlohmann::json::object();
  for (size_t i = 0; i < kFixRejectionCount; ++i)
    if (c.rejected[i] && i != static_cast<size_t>(FixRejection::kNoPosition))
      dropped[FixRejectionText(static_cast<FixRejection>(i))] = c.rejected[i];
  return {{"kept", c.kept}, {"dropped", dropped}};
}

nlohmann::json ExifJson(const io::ExifInfo& e) {
  nlohmann::json j = {{"make", e.make},
                      {"model", e.model},
                      {"focal_mm", e.focal_mm},
                      {"focal_35mm", e.focal_35mm},
                      {"datetime_original", e.datetime_original},
                      {"xmp_bytes", e.xmp.size()}};
  nlohmann::json g = nlohmann::json::object();
  Put(&g, "latitude", e.gps.latitude);
  Put(&g, "longitude", e.gps.longitude);
  Put(&g, "altitude", e.gps.altitude);
  Put(&g, "dop", e.gps.dop);
  Put(&g, "horizontal_error", e.gps.horizontal_error);
  Put(&g, "utc_seconds", e.gps.utc_seconds);
  if (e.gps.status) g["status"] = std::string(1, e.gps.status);
  if (e.gps.measure_mode) g["measure_mode"] = std::string(1, e.gps.measure_mode);
  if (!e.gps.map_datum.empty()) g["map_datum"] = e.gps.map_datum;
  j["gps"] = g;
  return j;
}

nlohmann::json DjiJson(const DjiXmp& d) {
  nlohmann::json j = {{"fields", d.fields}, {"malformed", d.malformed}};
  Put(&j, "GimbalYawDegree", d.gimbal_yaw);
  Put(&j, "GimbalPitchDegree", d.gimbal_pitch);
  Put(&j, "GimbalRollDegree", d.gimbal_roll);
  Put(&j, "FlightYawDegree", d.flight_yaw);
  Put(&j, "FlightPitchDegree", d.flight_pitch);
  Put(&j, "FlightRollDegree", d.flight_roll);
  Put(&j, "RelativeAltitude", d.relative_altitude);
  Put(&j, "AbsoluteAltitude", d.absolute_altitude);
  Put(&j, "GpsLatitude", d.latitude);
  Put(&j, "GpsLongitude", d.longitude);
  Put(&j, "RtkFlag", d.rtk_flag);
  Put(&j, "RtkStdLon", d.rtk_std_lon);
  Put(&j, "RtkStdLat", d.rtk_std_lat);
  Put(&j, "RtkStdHgt", d.rtk_std_hgt);
  return j;
}

nlohmann::json GpmfJson(const GpmfTelemetry& g) {
  nlohmann::json streams = nlohmann::json::object();
  for (const auto& [key, n] : g.stream_samples) {
    streams[key] = {{"samples", n}};
    const auto it = g.stream_names.find(key);
    if (it != g.stream_names.end()) streams[key]["name"] = it->second;
  }
  return {{"payloads", g.payloads},
          {"devices", g.devices},
          {"streams", streams},
          {"fixes", FixesJson(g.fixes)},
          {"entries", g.parse.entries},
          {"malformed", g.parse.malformed},
          {"unsupported", g.parse.unsupported}};
}

bool LooksLikeGpmf(const std::filesystem::path& p) {
  const std::string e = LowerExt(p);
  if (e == ".gpmf" || e == ".raw" || e == ".bin") return true;
  std::ifstream in(p, std::ios::binary);
  char head[4] = {0, 0, 0, 0};
  in.read(head, 4);
  return in.gcount() == 4 && std::equal(head, head + 4, "DEVC");
}

}  // namespace

nlohmann::json DumpTelemetry(const std::filesystem::path& input, const DumpOptions& o) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(input, ec)) throw Error(input.string() + ": no such file");
  nlohmann::json j = {{"input", input.string()}};
  if (io::HasImageExtension(input)) {
    const io::ExifInfo exif = io::ReadExif(input);
    const PhotoTelemetry t = TelemetryFromPhoto(exif, o.photo);
    j["kind"] = "photo";
    j["exif"] = ExifJson(exif);
    j["dji_xmp"] = DjiJson(t.dji);
    j["telemetry"] = t.sample ? ToJson(*t.sample) : nlohmann::json();
    if (!t.sample) j["rejected"] = FixRejectionText(t.rejection);
    return j;
  }
  if (LowerExt(input) == ".srt") {
    j["kind"] = "srt";
    j["samples"] = Samples(ReadDjiSrt(input));
    return j;
  }
  if (LooksLikeGpmf(input)) {
    std::ifstream in(input, std::ios::binary);
    GpmfPayload p;
    p.duration = 1;
    p.bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    const GpmfTelemetry g = TelemetryFromGpmf({p}, o.photo.fix);
    j["kind"] = "gpmf";
    j["gpmf"] = GpmfJson(g);
    j["samples"] = Samples(g.samples);
    return j;
  }
  j["kind"] = "video";
  TelemetryStats klv_stats;
  std::vector<TelemetrySample> samples = ReadVideoTelemetry(input, &klv_stats);
  j["klv_samples"] = samples.size();
  const GpmfTelemetry g = ReadGpmfTelemetry(input, o.photo.fix);
  if (g.payloads > 0) j["gpmf"] = GpmfJson(g);
  if (samples.empty()) samples = g.samples;
  if (samples.empty())
    if (auto srt = FindDjiSrtBeside(input)) {
      j["srt"] = srt->string();
      samples = ReadDjiSrt(*srt);
    }
  j["samples"] = Samples(samples);
  return j;
}

}  // namespace fmv3d::telemetry
