#include "fmv3d/server/validation.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <nlohmann/json.hpp>

namespace fmv3d::server {

namespace fs = std::filesystem;

const std::vector<std::string>& StageNames() {
  static const std::vector<std::string> names = {"frames", "features", "match", "sparse", "georef", "dense",
                                                 "mesh",   "texture",  "tiles", "dsm",    "ortho",  "report"};
  return names;
}

bool IsStageName(std::string_view name) {
  const auto& n = StageNames();
  return std::find(n.begin(), n.end(), name) != n.end();
}

namespace {
bool NameChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
         c == ' ' || c == '-';
}
}  // namespace

bool IsValidWorkspaceName(std::string_view name) {
  if (name.empty() || name.size() > 128 || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(), NameChar);
}

bool IsWithin(const fs::path& root, const fs::path& path) {
  auto r = root.begin(), p = path.begin();
  for (; r != root.end(); ++r, ++p) {
    if (r->empty() && std::next(r) == root.end()) break;  // a trailing separator of root
    if (p == path.end() || *p != *r) return false;
  }
  return true;
}

const char* PathRefusalText(PathRefusal refusal) {
  switch (refusal) {
    case PathRefusal::kNone:
      return "";
    case PathRefusal::kEmpty:
      return "empty path";
    case PathRefusal::kNulByte:
      return "NUL byte in path";
    case PathRefusal::kBackslash:
      return "backslash in path";
    case PathRefusal::kAbsolute:
      return "absolute path";
    case PathRefusal::kDotDot:
      return "'..' in path";
    case PathRefusal::kUnresolvable:
      return "path cannot be resolved";
    case PathRefusal::kLeavesRoot:
      return "path leaves its root";
  }
  return "";
}

ResolvedPath ResolveInside(const fs::path& root, std::string_view relative) {
  const auto fail = [](PathRefusal refusal) { return ResolvedPath{std::nullopt, refusal}; };
  if (relative.empty()) return fail(PathRefusal::kEmpty);
  if (relative.find('\0') != std::string_view::npos) return fail(PathRefusal::kNulByte);
  if (relative.find('\\') != std::string_view::npos) return fail(PathRefusal::kBackslash);
  const fs::path rel{std::string(relative)};
  if (rel.is_absolute() || relative.front() == '/') return fail(PathRefusal::kAbsolute);
  for (const auto& part : rel)
    if (part == "..") return fail(PathRefusal::kDotDot);
  std::error_code ec;
  fs::path resolved = fs::weakly_canonical(root / rel, ec);
  if (ec) return fail(PathRefusal::kUnresolvable);
  if (!IsWithin(root, resolved)) return fail(PathRefusal::kLeavesRoot);
  return {std::move(resolved), PathRefusal::kNone};
}

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  // Every byte of the longer string is visited whatever the content, and the length is folded in last.
  const size_t n = std::max(a.size(), b.size());
  unsigned char diff = 0;
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= x ^ y;
  }
  return diff == 0 && a.size() == b.size();
}

namespace {
nlohmann::json ParseObject(std::string_view body) {
  nlohmann::json j = nlohmann::json::parse(body.begin(), body.end(), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) throw RequestError(400, "the body is not valid JSON", "body");
  if (!j.is_object()) throw RequestError(400, "the body must be a JSON object", "body");
  return j;
}

std::string StageField(const nlohmann::json& j, const char* field) {
  if (!j.contains(field) || j[field].is_null()) return {};
  if (!j[field].is_string())
    throw RequestError(400, std::string("'") + field + "' must be a stage name (string)", field);
  std::string s = j[field].get<std::string>();
  if (s.empty()) return {};
  if (!IsStageName(s)) {
    std::string known;
    for (const auto& n : StageNames()) known += (known.empty() ? "" : ", ") + n;
    throw RequestError(400, std::string("'") + field + "': unknown stage (stages: " + known + ")", field);
  }
  return s;
}
}  // namespace

JobRequest ParseJobRequest(std::string_view body) {
  const nlohmann::json j = ParseObject(body);
  for (const auto& item : j.items())
    if (item.key() != "inputs" && item.key() != "from" && item.key() != "until" && item.key() != "fast")
      throw RequestError(400, "unknown field '" + item.key() + "' (fields: inputs, from, until, fast)", item.key());
  JobRequest r;
  if (j.contains("inputs") && !j["inputs"].is_null()) {
    if (!j["inputs"].is_array()) throw RequestError(400, "'inputs' must be an array of paths", "inputs");
    if (j["inputs"].size() > 10000) throw RequestError(400, "'inputs': too many paths", "inputs");
    for (const auto& in : j["inputs"]) {
      if (!in.is_string()) throw RequestError(400, "'inputs' must be an array of path strings", "inputs");
      const std::string s = in.get<std::string>();
      if (s.empty() || s.size() > 4096 || s.find('\0') != std::string::npos)
        throw RequestError(400, "'inputs': an empty, over-long or NUL-containing path", "inputs");
      r.inputs.push_back(s);
    }
  }
  r.from = StageField(j, "from");
  r.until = StageField(j, "until");
  if (!r.from.empty() && !r.until.empty()) {
    const auto& n = StageNames();
    if (std::find(n.begin(), n.end(), r.until) < std::find(n.begin(), n.end(), r.from))
      throw RequestError(400, "'until' comes before 'from'", "until");
  }
  if (j.contains("fast") && !j["fast"].is_null()) {
    if (!j["fast"].is_boolean()) throw RequestError(400, "'fast' must be true or false", "fast");
    r.fast = j["fast"].get<bool>();
  }
  return r;
}

std::string ParseCreateWorkspace(std::string_view body) {
  const nlohmann::json j = ParseObject(body);
  if (!j.contains("name")) throw RequestError(400, "'name' is required", "name");
  if (!j["name"].is_string()) throw RequestError(400, "'name' must be a string", "name");
  std::string name = j["name"].get<std::string>();
  if (!IsValidWorkspaceName(name))
    throw RequestError(400, "'name' must be 1-128 of [A-Za-z0-9._ -], not starting with '.'", "name");
  return name;
}

namespace {
std::optional<double> ParseDouble(std::string_view s) {
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  if (s.empty() || s.size() > 64) return std::nullopt;
  const std::string text(s);
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}
}  // namespace

LatLon ParseLatLon(std::string_view text, const std::string& field) {
  const size_t comma = text.find(',');
  if (comma == std::string_view::npos) throw RequestError(400, "'" + field + "' must be LAT,LON in degrees", field);
  const auto lat = ParseDouble(text.substr(0, comma)), lon = ParseDouble(text.substr(comma + 1));
  if (!lat || !lon) throw RequestError(400, "'" + field + "' must be LAT,LON in degrees", field);
  if (std::abs(*lat) > 90 || std::abs(*lon) > 180)
    throw RequestError(400, "'" + field + "': latitude within ±90, longitude within ±180", field);
  return {*lat, *lon};
}

int ParseBoundedInt(std::string_view text, int lo, int hi, const std::string& field) {
  int v = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || ptr != text.data() + text.size() || v < lo || v > hi)
    throw RequestError(
        400, "'" + field + "' must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", field);
  return v;
}

std::string SanitiseUploadName(std::string_view client_name) {
  const size_t slash = client_name.find_last_of("/\\");
  if (slash != std::string_view::npos) client_name.remove_prefix(slash + 1);
  std::string name;
  for (char c : client_name) name += NameChar(c) ? c : '_';
  // Shortened before the leading dots go: cutting afterwards could expose a '.' and make a hidden file.
  if (name.size() > 128) name.erase(0, name.size() - 128);
  while (!name.empty() && (name.front() == '.' || name.front() == ' ')) name.erase(name.begin());
  if (name.empty() || name.find_first_not_of('_') == std::string::npos)
    throw RequestError(400, "the uploaded file has no usable name", "file");
  return name;
}

}  // namespace fmv3d::server
