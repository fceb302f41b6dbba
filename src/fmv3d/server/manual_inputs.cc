#include "fmv3d/server/manual_inputs.h"

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <regex>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/geo/gcp_list.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/server/validation.h"

namespace fmv3d::server {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

json ParseObject(std::string_view body) {
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw RequestError(400, "the body is not a JSON object", "body");
  return j;
}

void OnlyKeys(const json& j, std::initializer_list<const char*> keys, const std::string& where) {
  for (const auto& [k, v] : j.items()) {
    bool ok = false;
    for (const char* key : keys) ok = ok || k == key;
    if (!ok) throw RequestError(400, fmt::format("{}: unknown field '{}'", where, k), k);
  }
}

double Number(const json& j, const char* key, const std::string& where) {
  if (!j.contains(key) || !j[key].is_number() || !std::isfinite(j[key].get<double>()))
    throw RequestError(400, where + ": '" + key + "' must be a finite number", key);
  return j[key].get<double>();
}

std::string String(const json& j, const char* key, const std::string& where) {
  if (!j.contains(key) || !j[key].is_string() || j[key].get<std::string>().empty())
    throw RequestError(400, where + ": '" + key + "' must be a non-empty string", key);
  return j[key].get<std::string>();
}

json Array(const json& j, const char* key) {
  if (!j.contains(key)) return json::array();
  if (!j[key].is_array()) throw RequestError(400, std::string("'") + key + "' must be an array", key);
  return j[key];
}

void ThrowIfAny(const std::vector<std::string>& errors, const std::string& field) {
  if (!errors.empty()) throw RequestError(400, io::JoinErrors(errors), field);
}

json GcpsToJson(const geo::GcpList& list) {
  json points = json::array();
  for (const auto& p : geo::GroupGcps(list)) {
    json obs = json::array();
    for (const auto& o : p.observations) obs.push_back({{"frame", o.frame}, {"x", o.x}, {"y", o.y}});
    points.push_back({{"name", p.name},
                      {"x", p.geo.x()},
                      {"y", p.geo.y()},
                      {"z", p.geo.z()},
                      {"check", p.check},
                      {"observations", obs}});
  }
  return {{"crs", list.crs}, {"points", points}};
}

// Checks a parsed list (frames, pixels; every point in ≥ 2 frames) and writes it atomically.
json CheckAndWriteGcps(const geo::GcpList& list, const io::FrameTable& frames, const fs::path& path) {
  std::vector<std::string> errors;
  geo::CheckGcpList(list, frames, &errors);  // names a point clicked in fewer than 2 frames too
  ThrowIfAny(errors, "points");
  try {
    geo::WriteGcpList(list, path, &frames);
  } catch (const Error& e) {
    throw RequestError(400, e.what(), "points");
  }
  return GcpsToJson(list);
}

}  // namespace

json SaveTiePoints(std::string_view body, const io::FrameTable& frames, const fs::path& path) {
  std::vector<std::string> errors;
  const io::TiePoints t = io::ParseTiePoints(std::string(body), &errors);
  ThrowIfAny(errors, "tie_points");
  io::CheckTiePoints(t, frames, &errors);
  ThrowIfAny(errors, "tie_points");
  try {
    io::WriteTiePoints(t, path, &frames);
  } catch (const Error& e) {
    throw RequestError(400, e.what(), "tie_points");
  }
  return io::TiePointsToJson(t);
}

json LoadTiePoints(const fs::path& path) {
  if (!fs::exists(path)) return io::TiePointsToJson(io::TiePoints{});
  return io::TiePointsToJson(io::ReadTiePoints(path));
}

json SaveGcpText(std::string_view text, const io::FrameTable& frames, const fs::path& path) {
  std::vector<std::string> errors;
  const geo::GcpList list = geo::ParseGcpList(std::string(text), &errors);
  ThrowIfAny(errors, "file");
  return CheckAndWriteGcps(list, frames, path);
}

json SaveGcpJson(std::string_view body, const io::FrameTable& frames, const fs::path& path) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"crs", "points"}, "GCPs");
  geo::GcpList list;
  list.crs = String(j, "crs", "GCPs");
  try {
    geo::GcpCrs crs(list.crs);
  } catch (const Error& e) {
    throw RequestError(400, e.what(), "crs");
  }
  const json points = Array(j, "points");
  for (size_t i = 0; i < points.size(); ++i) {
    const json& p = points[i];
    std::string where = "GCP " + std::to_string(i + 1);
    if (!p.is_object()) throw RequestError(400, where + " is not an object", "points");
    OnlyKeys(p, {"name", "x", "y", "z", "check", "observations"}, where);
    const std::string name = String(p, "name", where);
    if (name.find_first_of(" \t\r\n") != std::string::npos)
      throw RequestError(400, fmt::format("{}: the name '{}' must not contain spaces", where, name), "name");
    where = "GCP '" + name + "'";
    const Eigen::Vector3d geo(Number(p, "x", where), Number(p, "y", where), Number(p, "z", where));
    if (p.contains("check") && !p["check"].is_boolean())
      throw RequestError(400, where + ": 'check' must be true or false", "check");
    const json obs = Array(p, "observations");
    if (obs.size() < 2)
      throw RequestError(400,
                         where + " is marked in " + std::to_string(obs.size()) + " frame(s); mark it in at least 2",
                         "observations");
    for (size_t k = 0; k < obs.size(); ++k) {
      const std::string w = where + ", observation " + std::to_string(k + 1);
      if (!obs[k].is_object()) throw RequestError(400, w + " is not an object", "observations");
      OnlyKeys(obs[k], {"frame", "x", "y"}, w);
      geo::GcpLine line;
      line.geo = geo;
      line.image = String(obs[k], "frame", w);
      line.im_x = Number(obs[k], "x", w);
      line.im_y = Number(obs[k], "y", w);
      line.name = name;
      if (p.value("check", false)) line.extra = {"check"};
      list.lines.push_back(line);
    }
  }
  // The formatted text parsed again: the same checks an imported file gets.
  std::vector<std::string> errors;
  const geo::GcpList reparsed = geo::ParseGcpList(geo::FormatGcpList(list), &errors);
  ThrowIfAny(errors, "points");
  return CheckAndWriteGcps(reparsed, frames, path);
}

json LoadGcps(const fs::path& path) {
  if (!fs::exists(path)) return {{"crs", nullptr}, {"points", json::array()}};
  return GcpsToJson(geo::ReadGcpList(path));
}

CalibrationRequest ParseCalibrationRequest(std::string_view body) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"images", "board", "square", "drop"}, "calibration");
  CalibrationRequest r;
  const json images = Array(j, "images");
  bool any_video = false;
  for (const auto& i : images) {
    if (!i.is_string() || i.get<std::string>().empty())
      throw RequestError(400, "'images' must be workspace-relative paths", "images");
    r.images.push_back(i.get<std::string>());
    any_video = any_video || io::HasVideoExtension(r.images.back());
  }
  if (images.size() < 3 && !any_video)
    throw RequestError(400, "'images': choose at least 3 chessboard images, or a calibration video", "images");
  if (j.contains("drop")) {
    for (const auto& d : Array(j, "drop")) {
      if (!d.is_string() || !std::regex_match(d.get<std::string>(), std::regex(R"([A-Za-z0-9._ -]{1,255})")))
        throw RequestError(400, "'drop': file names of images or video frames (no folders)", "drop");
      r.drop.push_back(d.get<std::string>());
    }
  }
  if (j.contains("board")) {
    const json& b = j["board"];
    std::smatch m;
    std::string text = b.is_string() ? b.get<std::string>() : "";
    if (b.is_object() && b.contains("cols") && b.contains("rows") && b["cols"].is_number_integer() &&
        b["rows"].is_number_integer()) {
      r.cols = b["cols"], r.rows = b["rows"];
    } else if (std::regex_match(text, m, std::regex(R"((\d{1,3})x(\d{1,3}))"))) {
      r.cols = std::stoi(m[1]), r.rows = std::stoi(m[2]);
    } else {
      throw RequestError(400, "'board': inner corners as \"COLSxROWS\" (e.g. \"9x6\")", "board");
    }
    if (r.cols < 2 || r.rows < 2 || r.cols > 100 || r.rows > 100)
      throw RequestError(400, "'board': between 2 and 100 inner corners per side", "board");
  }
  if (j.contains("square")) {
    r.square = Number(j, "square", "calibration");
    if (r.square <= 0 || r.square > 10)
      throw RequestError(400, "'square': the square side in metres (0, 10]", "square");
  }
  return r;
}

std::string ParseSensorName(std::string_view body) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"name"}, "sensor");
  std::string name = String(j, "name", "sensor");
  if (name.size() > 64 || !std::regex_match(name, std::regex(R"([A-Za-z0-9._ -]+)")))
    throw RequestError(400, "'name': 1 to 64 characters of letters, digits, '.', '_', ' ' and '-'", "name");
  return name;
}

}  // namespace fmv3d::server
