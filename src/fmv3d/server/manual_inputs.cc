#include "fmv3d/server/manual_inputs.h"

#include <proj.h>

#include <cmath>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "fmv3d/server/validation.h"

namespace fmv3d::server {

namespace {

using nlohmann::json;

json ParseObject(std::string_view body) {
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded() || !j.is_object()) throw RequestError(400, "the body is not a JSON object", "body");
  return j;
}

void OnlyKeys(const json& j, std::initializer_list<const char*> keys, const std::string& where) {
  for (const auto& [k, v] : j.items()) {
    bool ok = false;
    for (const char* key : keys) ok = ok || k == key;
    if (!ok) throw RequestError(400, where + ": unknown field '" + k + "'", k);
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

const FrameSize& Frame(const std::vector<FrameSize>& frames, const std::string& name, const std::string& where) {
  for (const auto& f : frames)
    if (f.name == name) return f;
  throw RequestError(400, where + ": frame '" + name + "' does not exist in this workspace", "image");
}

void InsideImage(const FrameSize& f, double x, double y, const std::string& where) {
  if (x < 0 || y < 0 || x > f.width || y > f.height) {
    std::ostringstream m;
    m << where << ": (" << x << ", " << y << ") is outside frame '" << f.name << "' (" << f.width << " x "
      << f.height << " px)";
    throw RequestError(400, m.str(), "x");
  }
}

// An observation {"image", "x", "y"} in a frame of the workspace, inside the image.
json Observation(const json& o, const std::vector<FrameSize>& frames, const std::string& where) {
  if (!o.is_object()) throw RequestError(400, where + " is not an object", "observations");
  OnlyKeys(o, {"image", "x", "y"}, where);
  const std::string image = String(o, "image", where);
  const double x = Number(o, "x", where), y = Number(o, "y", where);
  InsideImage(Frame(frames, image, where), x, y, where);
  return {{"image", image}, {"x", x}, {"y", y}};
}

json Array(const json& j, const char* key) {
  if (!j.contains(key)) return json::array();
  if (!j[key].is_array()) throw RequestError(400, std::string("'") + key + "' must be an array", key);
  return j[key];
}

// The CRS line of a gcp_list.txt as PROJ understands it ("WGS84 UTM 32N" → "EPSG:32632"); throws for a CRS
// PROJ does not know.
std::string CheckCrs(std::string crs) {
  while (!crs.empty() && std::isspace(static_cast<unsigned char>(crs.back()))) crs.pop_back();
  std::smatch m;
  if (std::regex_match(crs, m, std::regex(R"(WGS84 UTM (\d{1,2})([NSns]))")))
    crs = "EPSG:" + std::to_string((std::toupper(m[2].str()[0]) == 'N' ? 32600 : 32700) + std::stoi(m[1]));
  if (std::regex_match(crs, std::regex(R"(epsg:\d+)", std::regex::icase))) crs = "EPSG:" + crs.substr(5);
  PJ_CONTEXT* ctx = proj_context_create();
  proj_log_level(ctx, PJ_LOG_NONE);
  PJ* pj = proj_create(ctx, crs.c_str());
  const bool ok = pj && proj_is_crs(pj);
  if (pj) proj_destroy(pj);
  proj_context_destroy(ctx);
  if (!ok)
    throw RequestError(400,
                       "unknown coordinate reference system '" + crs +
                           "' (use EPSG:N with a code PROJ knows, 'WGS84 UTM 32N' or a PROJ string)",
                       "crs");
  return crs;
}

struct GcpPoint {
  double x = 0, y = 0, z = 0;
  bool check = false;
  json observations = json::array();
};

// Groups observations by GCP name and checks the whole set.
json FinishGcps(const std::string& crs, const std::vector<std::string>& order, std::map<std::string, GcpPoint>& pts) {
  json points = json::array();
  for (const auto& name : order) {
    const GcpPoint& p = pts[name];
    if (p.observations.size() < 2)
      throw RequestError(400,
                         "GCP '" + name + "' is marked in " + std::to_string(p.observations.size()) +
                             " frame(s); mark it in at least 2",
                         "observations");
    points.push_back({{"name", name}, {"x", p.x}, {"y", p.y}, {"z", p.z}, {"check", p.check},
                      {"observations", p.observations}});
  }
  return {{"crs", crs}, {"points", points}};
}

void AddGcpObservation(std::vector<std::string>* order, std::map<std::string, GcpPoint>* pts, const std::string& name,
                       const GcpPoint& coords, const json& obs, const std::string& where) {
  auto it = pts->find(name);
  if (it == pts->end()) {
    order->push_back(name);
    it = pts->emplace(name, coords).first;
    it->second.observations = json::array();
  } else if (std::abs(it->second.x - coords.x) > 1e-9 || std::abs(it->second.y - coords.y) > 1e-9 ||
             std::abs(it->second.z - coords.z) > 1e-9) {
    throw RequestError(400, where + ": GCP '" + name + "' has other coordinates on an earlier line", "points");
  } else if (it->second.check != coords.check) {
    throw RequestError(400, where + ": GCP '" + name + "' is a check point on one line and not on another",
                       "check");
  }
  for (const auto& o : it->second.observations)
    if (o["image"] == obs["image"])
      throw RequestError(400, where + ": GCP '" + name + "' is marked twice in frame '" +
                                  obs["image"].get<std::string>() + "'",
                         "observations");
  it->second.observations.push_back(obs);
}

}  // namespace

json EmptyTiePoints() {
  return {{"version", 1},
          {"tiepoints", json::array()},
          {"points_of_interest", json::array()},
          {"removed_matches", json::array()}};
}

json ValidateTiePoints(std::string_view body, const std::vector<FrameSize>& frames) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"version", "tiepoints", "points_of_interest", "removed_matches"}, "tie points");
  if (j.contains("version") && j["version"] != 1)
    throw RequestError(400, "'version': only version 1 of manual/tiepoints.json is known", "version");
  json out = EmptyTiePoints();
  std::set<std::string> ids;
  auto unique_id = [&](const json& t, const std::string& where) {
    const std::string id = String(t, "id", where);
    if (!ids.insert(id).second) throw RequestError(400, where + ": id '" + id + "' is used twice", "id");
    return id;
  };
  const json tps = Array(j, "tiepoints");
  for (size_t i = 0; i < tps.size(); ++i) {
    const json& t = tps[i];
    std::string where = "tie point " + std::to_string(i + 1);
    if (!t.is_object()) throw RequestError(400, where + " is not an object", "tiepoints");
    OnlyKeys(t, {"id", "observations"}, where);
    const std::string id = unique_id(t, where);
    where = "tie point '" + id + "'";
    const json obs = Array(t, "observations");
    if (obs.size() < 2)
      throw RequestError(400, where + " has " + std::to_string(obs.size()) +
                                  " observation(s); a tie point needs at least 2 (one per frame)",
                         "observations");
    json clean = json::array();
    std::set<std::string> images;
    for (size_t k = 0; k < obs.size(); ++k) {
      const json o = Observation(obs[k], frames, where + ", observation " + std::to_string(k + 1));
      if (!images.insert(o["image"].get<std::string>()).second)
        throw RequestError(400, where + " has two observations in frame '" + o["image"].get<std::string>() + "'",
                           "observations");
      clean.push_back(o);
    }
    out["tiepoints"].push_back({{"id", id}, {"observations", clean}});
  }
  const json pois = Array(j, "points_of_interest");
  for (size_t i = 0; i < pois.size(); ++i) {
    const json& p = pois[i];
    std::string where = "point of interest " + std::to_string(i + 1);
    if (!p.is_object()) throw RequestError(400, where + " is not an object", "points_of_interest");
    OnlyKeys(p, {"id", "image", "x", "y"}, where);
    const std::string id = unique_id(p, where);
    json o = Observation({{"image", p.value("image", json())}, {"x", p.value("x", json())}, {"y", p.value("y", json())}},
                         frames, "point of interest '" + id + "'");
    o["id"] = id;
    out["points_of_interest"].push_back(o);
  }
  const json removed = Array(j, "removed_matches");
  for (size_t i = 0; i < removed.size(); ++i) {
    const json& r = removed[i];
    const std::string where = "removed match " + std::to_string(i + 1);
    if (!r.is_object()) throw RequestError(400, where + " is not an object", "removed_matches");
    OnlyKeys(r, {"image1", "image2", "x1", "y1", "x2", "y2"}, where);
    const json a = Observation({{"image", r.value("image1", json())}, {"x", r.value("x1", json())},
                                {"y", r.value("y1", json())}},
                               frames, where);
    const json b = Observation({{"image", r.value("image2", json())}, {"x", r.value("x2", json())},
                                {"y", r.value("y2", json())}},
                               frames, where);
    if (a["image"] == b["image"]) throw RequestError(400, where + ": both ends are in one frame", "removed_matches");
    out["removed_matches"].push_back({{"image1", a["image"]}, {"x1", a["x"]}, {"y1", a["y"]},
                                      {"image2", b["image"]}, {"x2", b["x"]}, {"y2", b["y"]}});
  }
  return out;
}

json ParseGcpText(std::string_view text, const std::vector<FrameSize>& frames) {
  std::istringstream in{std::string(text)};
  std::string line, crs;
  int line_no = 0;
  std::vector<std::string> order;
  std::map<std::string, GcpPoint> pts;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos || line[line.find_first_not_of(" \t")] == '#') continue;
    const std::string where = "gcp_list.txt line " + std::to_string(line_no);
    if (crs.empty()) {
      try {
        crs = CheckCrs(line);
      } catch (const RequestError& e) {
        throw RequestError(400, where + ": " + e.what(), "crs");
      }
      continue;
    }
    std::istringstream cols(line);
    std::vector<std::string> c;
    for (std::string w; cols >> w;) c.push_back(w);
    if (c.size() < 6)
      throw RequestError(400, where + ": " + std::to_string(c.size()) +
                                  " columns; expected 'geo_x geo_y geo_z im_x im_y image_name [gcp_name] [check]'",
                         "line");
    double v[5];
    for (int k = 0; k < 5; ++k) {
      size_t used = 0;
      try {
        v[k] = std::stod(c[k], &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != c[k].size() || !std::isfinite(v[k]))
        throw RequestError(400, where + ": column " + std::to_string(k + 1) + " ('" + c[k] + "') is not a number",
                           "line");
    }
    GcpPoint coords;
    coords.x = v[0], coords.y = v[1], coords.z = v[2];
    coords.check = c.size() >= 8 && (c[7] == "check" || c[7] == "CHECK");
    const std::string name = c.size() >= 7 ? c[6] : "gcp-" + std::to_string(pts.size() + 1);
    const json obs = Observation({{"image", c[5]}, {"x", v[3]}, {"y", v[4]}}, frames, where);
    AddGcpObservation(&order, &pts, name, coords, obs, where);
  }
  if (crs.empty()) throw RequestError(400, "gcp_list.txt is empty: the first line must name the CRS", "crs");
  return FinishGcps(crs, order, pts);
}

json GcpsFromJson(std::string_view body, const std::vector<FrameSize>& frames) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"crs", "points"}, "GCPs");
  const std::string crs = CheckCrs(String(j, "crs", "GCPs"));
  std::vector<std::string> order;
  std::map<std::string, GcpPoint> pts;
  const json points = Array(j, "points");
  for (size_t i = 0; i < points.size(); ++i) {
    const json& p = points[i];
    std::string where = "GCP " + std::to_string(i + 1);
    if (!p.is_object()) throw RequestError(400, where + " is not an object", "points");
    OnlyKeys(p, {"name", "x", "y", "z", "check", "observations"}, where);
    const std::string name = String(p, "name", where);
    if (name.find_first_of(" \t\r\n") != std::string::npos)
      throw RequestError(400, where + ": the name '" + name + "' must not contain spaces", "name");
    if (pts.count(name)) throw RequestError(400, where + ": the name '" + name + "' is used twice", "name");
    where = "GCP '" + name + "'";
    GcpPoint coords;
    coords.x = Number(p, "x", where), coords.y = Number(p, "y", where), coords.z = Number(p, "z", where);
    if (p.contains("check") && !p["check"].is_boolean())
      throw RequestError(400, where + ": 'check' must be true or false", "check");
    coords.check = p.value("check", false);
    const json obs = Array(p, "observations");
    if (obs.empty()) order.push_back(name), pts.emplace(name, coords);
    for (size_t k = 0; k < obs.size(); ++k)
      AddGcpObservation(&order, &pts, name, coords,
                        Observation(obs[k], frames, where + ", observation " + std::to_string(k + 1)),
                        where + ", observation " + std::to_string(k + 1));
  }
  return FinishGcps(crs, order, pts);
}

std::string FormatGcpText(const json& gcps) {
  std::ostringstream out;
  out.precision(12);
  out << gcps["crs"].get<std::string>() << "\n";
  for (const auto& p : gcps["points"])
    for (const auto& o : p["observations"]) {
      out << p["x"].get<double>() << ' ' << p["y"].get<double>() << ' ' << p["z"].get<double>() << ' '
          << o["x"].get<double>() << ' ' << o["y"].get<double>() << ' ' << o["image"].get<std::string>() << ' '
          << p["name"].get<std::string>();
      if (p["check"].get<bool>()) out << " check";
      out << "\n";
    }
  return out.str();
}

CalibrationRequest ParseCalibrationRequest(std::string_view body) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"images", "board", "square"}, "calibration");
  CalibrationRequest r;
  const json images = Array(j, "images");
  if (images.size() < 3) throw RequestError(400, "'images': choose at least 3 chessboard images", "images");
  for (const auto& i : images) {
    if (!i.is_string() || i.get<std::string>().empty())
      throw RequestError(400, "'images' must be workspace-relative paths", "images");
    r.images.push_back(i.get<std::string>());
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
    if (r.square <= 0 || r.square > 10) throw RequestError(400, "'square': the square side in metres (0, 10]", "square");
  }
  return r;
}

std::string ParseSensorName(std::string_view body) {
  const json j = ParseObject(body);
  OnlyKeys(j, {"name"}, "sensor");
  const std::string name = String(j, "name", "sensor");
  if (name.size() > 64 || !std::regex_match(name, std::regex(R"([A-Za-z0-9._ -]+)")))
    throw RequestError(400, "'name': 1 to 64 characters of letters, digits, '.', '_', ' ' and '-'", "name");
  return name;
}

}  // namespace fmv3d::server
