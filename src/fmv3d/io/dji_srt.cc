#include "fmv3d/io/dji_srt.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <regex>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {

namespace {

std::optional<double> ParseNumber(const std::string& s) {
  try {
    size_t used = 0;
    const double v = std::stod(s, &used);
    if (!std::isfinite(v)) return std::nullopt;
    return v;
  } catch (...) {
    return std::nullopt;
  }
}

// "HH:MM:SS,mmm" (a '.' is accepted for the comma) -> seconds.
std::optional<double> ParseSrtTime(const std::string& s) {
  static const std::regex re(R"(^\s*(\d+):(\d{1,2}):(\d{1,2})[,.](\d{1,3}))");
  std::smatch m;
  if (!std::regex_search(s, m, re)) return std::nullopt;
  const std::string ms = m[4].str();
  return std::stod(m[1]) * 3600 + std::stod(m[2]) * 60 + std::stod(m[3]) +
         std::stod(ms) / std::pow(10.0, static_cast<double>(ms.size()));
}

void ParseBlock(const std::vector<std::string>& lines, std::vector<TelemetrySample>* out) {
  // Find the timing line; the text is everything after it.
  size_t i = 0;
  std::optional<double> start;
  for (; i < lines.size(); ++i) {
    const auto arrow = lines[i].find("-->");
    if (arrow != std::string::npos) {
      start = ParseSrtTime(lines[i].substr(0, arrow));
      ++i;
      break;
    }
  }
  if (!start) return;
  std::string text;
  for (; i < lines.size(); ++i) text += lines[i] + " ";

  TelemetrySample s;
  s.time = *start;
  s.source = "DJI-SRT";
  // Older layout: GPS(lon,lat,alt) BAROMETER:x
  static const std::regex gps(R"(GPS\s*\(\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*(?:,\s*([-+0-9.eE]+)\s*M?)?\s*\))");
  static const std::regex baro(R"(BAROMETER\s*:\s*([-+0-9.eE]+))");
  // Newer layout: "name: value" pairs, several per [...] group.
  static const std::regex pair(R"(([A-Za-z_]+)\s*:\s*([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?))");
  std::smatch m;
  if (std::regex_search(text, m, gps)) {
    s.sensor_longitude = ParseNumber(m[1]);
    s.sensor_latitude = ParseNumber(m[2]);
    if (m[3].matched) s.sensor_altitude_msl = ParseNumber(m[3]);
    if (std::regex_search(text, m, baro)) s.sensor_relative_altitude = ParseNumber(m[1]);
  } else {
    std::map<std::string, double> kv;
    for (auto it = std::sregex_iterator(text.begin(), text.end(), pair); it != std::sregex_iterator(); ++it) {
      std::string key = (*it)[1].str();
      std::transform(key.begin(), key.end(), key.begin(), [](unsigned char c) { return std::tolower(c); });
      if (const auto v = ParseNumber((*it)[2].str())) kv.emplace(key, *v);
    }
    auto get = [&](const char* k) -> std::optional<double> {
      const auto f = kv.find(k);
      return f == kv.end() ? std::nullopt : std::optional<double>(f->second);
    };
    s.sensor_latitude = get("latitude");
    s.sensor_longitude = get("longitude");
    if (!s.sensor_longitude) s.sensor_longitude = get("longtitude");  // a spelling some firmwares write
    s.sensor_altitude_msl = get("abs_alt");
    if (!s.sensor_altitude_msl) s.sensor_altitude_msl = get("altitude");
    s.sensor_relative_altitude = get("rel_alt");
    s.gimbal_yaw = get("gb_yaw");
    s.gimbal_pitch = get("gb_pitch");
    s.gimbal_roll = get("gb_roll");
  }
  if (!s.sensor_latitude || !s.sensor_longitude) return;
  if (*s.sensor_latitude == 0 && *s.sensor_longitude == 0) return;  // no fix
  if (std::abs(*s.sensor_latitude) > 90 || std::abs(*s.sensor_longitude) > 180) return;
  out->push_back(std::move(s));
}

}  // namespace

std::vector<TelemetrySample> ParseDjiSrt(const std::string& text) {
  std::vector<TelemetrySample> out;
  std::istringstream in(text);
  std::string line;
  std::vector<std::string> block;
  auto flush = [&] {
    if (!block.empty()) ParseBlock(block, &out);
    block.clear();
  };
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.size() >= 3 && static_cast<unsigned char>(line[0]) == 0xEF &&
        static_cast<unsigned char>(line[1]) == 0xBB && static_cast<unsigned char>(line[2]) == 0xBF)
      line.erase(0, 3);  // UTF-8 BOM
    const bool blank = line.find_first_not_of(" \t") == std::string::npos;
    if (blank)
      flush();
    else
      block.push_back(line);
  }
  flush();
  std::stable_sort(out.begin(), out.end(),
                   [](const TelemetrySample& a, const TelemetrySample& b) { return a.time < b.time; });
  return out;
}

std::vector<TelemetrySample> ReadDjiSrt(const std::filesystem::path& path) {
  return ParseDjiSrt(core::ReadTextFile(path));
}

std::optional<std::filesystem::path> FindDjiSrtBeside(const std::filesystem::path& video) {
  for (const char* ext : {".SRT", ".srt"}) {
    auto p = video;
    p.replace_extension(ext);
    std::error_code ec;
    if (std::filesystem::is_regular_file(p, ec)) return p;
  }
  return std::nullopt;
}

}  // namespace fmv3d::io
