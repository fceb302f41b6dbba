#include "fmv3d/telemetry/dji_srt.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <map>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::telemetry {

namespace {

bool IsIdent(char c) { return std::isalpha(static_cast<unsigned char>(c)) || c == '_'; }
bool IsDigit(char c) { return c >= '0' && c <= '9'; }

size_t SkipSpaces(const std::string& s, size_t i) {
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
  return i;
}

// A decimal number at s[i] ([+-]digits[.digits][e[+-]digits], locale-independent); advances i past it.
// Hand-written rather than std::regex: libstdc++'s regex recurses per character and can overflow the stack
// on long hostile lines.
std::optional<double> ScanNumber(const std::string& s, size_t* i) {
  size_t j = *i;
  if (j < s.size() && (s[j] == '+' || s[j] == '-')) ++j;
  const size_t digits_start = j;
  while (j < s.size() && IsDigit(s[j])) ++j;
  size_t n_digits = j - digits_start;
  if (j < s.size() && s[j] == '.') {
    ++j;
    const size_t f = j;
    while (j < s.size() && IsDigit(s[j])) ++j;
    n_digits += j - f;
  }
  if (n_digits == 0) return std::nullopt;
  if (j < s.size() && (s[j] == 'e' || s[j] == 'E')) {
    size_t k = j + 1;
    if (k < s.size() && (s[k] == '+' || s[k] == '-')) ++k;
    if (k < s.size() && IsDigit(s[k])) {
      while (k < s.size() && IsDigit(s[k])) ++k;
      j = k;
    }
  }
  const char* first = s.data() + *i + (s[*i] == '+' ? 1 : 0);
  double v = 0;
  const auto res = std::from_chars(first, s.data() + j, v);
  if (res.ec != std::errc() || !std::isfinite(v)) return std::nullopt;
  *i = j;
  return v;
}

// "HH:MM:SS,mmm" (a '.' is accepted for the comma) -> seconds.
std::optional<double> ParseSrtTime(const std::string& s) {
  size_t i = SkipSpaces(s, 0);
  double parts[3] = {0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    const size_t b = i;
    while (i < s.size() && IsDigit(s[i]) && i - b < 6) ++i;
    if (i == b) return std::nullopt;
    parts[k] = std::stod(s.substr(b, i - b));
    const char sep = k < 2 ? ':' : ',';
    if (i >= s.size() || (s[i] != sep && !(k == 2 && s[i] == '.'))) return std::nullopt;
    ++i;
  }
  const size_t b = i;
  while (i < s.size() && IsDigit(s[i]) && i - b < 3) ++i;
  if (i == b) return std::nullopt;
  const double frac = std::stod(s.substr(b, i - b)) / std::pow(10.0, static_cast<double>(i - b));
  return parts[0] * 3600 + parts[1] * 60 + parts[2] + frac;
}

// Older layout: "GPS(lon,lat[,alt])", numbers optionally followed by a unit letter.
bool ScanGps(const std::string& text, std::vector<double>* values) {
  const size_t at = text.find("GPS");
  if (at == std::string::npos) return false;
  size_t i = SkipSpaces(text, at + 3);
  if (i >= text.size() || text[i] != '(') return false;
  ++i;
  while (true) {
    i = SkipSpaces(text, i);
    const auto v = ScanNumber(text, &i);
    if (!v) return false;
    values->push_back(*v);
    i = SkipSpaces(text, i);
    if (i < text.size() && std::isalpha(static_cast<unsigned char>(text[i]))) i = SkipSpaces(text, i + 1);
    if (i < text.size() && text[i] == ',') {
      ++i;
      continue;
    }
    return i < text.size() && text[i] == ')' && values->size() >= 2;
  }
}

// Every "name: number" pair (names lower-cased); the first occurrence of a name wins.
std::map<std::string, double> ScanPairs(const std::string& text) {
  std::map<std::string, double> kv;
  size_t i = 0;
  while (i < text.size()) {
    if (!IsIdent(text[i]) || (i > 0 && IsIdent(text[i - 1]))) {
      ++i;
      continue;
    }
    const size_t b = i;
    while (i < text.size() && IsIdent(text[i])) ++i;
    std::string key = text.substr(b, i - b);
    size_t j = SkipSpaces(text, i);
    if (j >= text.size() || text[j] != ':') continue;
    j = SkipSpaces(text, j + 1);
    if (const auto v = ScanNumber(text, &j)) {
      std::transform(key.begin(), key.end(), key.begin(), [](unsigned char c) { return std::tolower(c); });
      kv.emplace(std::move(key), *v);
      i = j;
    }
  }
  return kv;
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
  std::vector<double> gps;
  const auto kv = ScanPairs(text);
  auto get = [&](const char* k) -> std::optional<double> {
    const auto f = kv.find(k);
    return f == kv.end() ? std::nullopt : std::optional<double>(f->second);
  };
  if (ScanGps(text, &gps)) {
    s.sensor_longitude = gps[0];
    s.sensor_latitude = gps[1];
    if (gps.size() > 2) s.sensor_altitude_msl = gps[2];
    s.sensor_relative_altitude = get("barometer");
  } else {
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

}  // namespace fmv3d::telemetry
