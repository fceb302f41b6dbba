#include "fmv3d/calib/sensor_db.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::calib {
namespace fs = std::filesystem;

namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

fs::path ExeDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

SensorEntry EntryFromJson(const nlohmann::json& j, const fs::path& origin) {
  SensorEntry e;
  e.name = j.at("name").get<std::string>();
  e.make = j.value("make", "");
  if (j.contains("models")) e.models = j["models"].get<std::vector<std::string>>();
  if (j.contains("model")) e.models.push_back(j["model"].get<std::string>());
  e.sensor_width_mm = j.value("sensor_width_mm", 0.0);
  e.sensor_height_mm = j.value("sensor_height_mm", 0.0);
  e.focal_mm = j.value("focal_mm", 0.0);
  e.focal_35mm = j.value("focal_35mm", 0.0);
  if (j.contains("resolution")) {
    e.width = j["resolution"].at(0).get<int>();
    e.height = j["resolution"].at(1).get<int>();
  }
  if (j.contains("calibration")) {
    const auto& c = j["calibration"];
    core::Camera cam;
    cam.width = c.at("width").get<int>();
    cam.height = c.at("height").get<int>();
    core::IntrinsicsFromJson(c, &cam);
    cam.Validate();
    e.calibration = cam;
    if (e.width == 0) {
      e.width = cam.width;
      e.height = cam.height;
    }
  }
  e.note = j.value("note", "");
  e.origin = origin.string();
  if (e.name.empty()) throw Error("an entry has an empty name");
  return e;
}

}  // namespace

nlohmann::json SensorToJson(const SensorEntry& e) {
  nlohmann::json j = {{"name", e.name}};
  if (!e.make.empty()) j["make"] = e.make;
  if (!e.models.empty()) j["models"] = e.models;
  if (e.sensor_width_mm > 0) j["sensor_width_mm"] = e.sensor_width_mm;
  if (e.sensor_height_mm > 0) j["sensor_height_mm"] = e.sensor_height_mm;
  if (e.focal_mm > 0) j["focal_mm"] = e.focal_mm;
  if (e.focal_35mm > 0) j["focal_35mm"] = e.focal_35mm;
  if (e.width > 0) j["resolution"] = {e.width, e.height};
  if (e.calibration) {
    const auto& c = *e.calibration;
    j["calibration"] = core::CameraToJson(c);
  }
  if (!e.note.empty()) j["note"] = e.note;
  return j;
}

fs::path ShippedDatabasePath() {
  if (const char* env = std::getenv("FMV3D_SENSOR_DB")) return env;
  std::vector<fs::path> candidates;
  const fs::path exe = ExeDir();
  if (!exe.empty()) {
    candidates.push_back(exe / ".." / "share" / "fmv3d" / "sensors.json");
    candidates.push_back(exe / ".." / "data" / "sensors.json");
    candidates.push_back(exe / ".." / ".." / "data" / "sensors.json");
  }
  // Development builds: the source tree (this file is src/fmv3d/calib/sensor_db.cc).
  candidates.push_back(fs::path(__FILE__).parent_path() / ".." / ".." / ".." / "data" / "sensors.json");
  for (const auto& c : candidates) {
    std::error_code ec;
    if (fs::is_regular_file(c, ec)) return fs::weakly_canonical(c, ec);
  }
  return {};
}

fs::path UserDatabasePath() {
  if (const char* env = std::getenv("FMV3D_USER_SENSORS")) return env;
  if (const char* xdg = std::getenv("XDG_CONFIG_HOME"); xdg && *xdg) return fs::path(xdg) / "fmv3d" / "sensors.json";
  if (const char* home = std::getenv("HOME"); home && *home)
    return fs::path(home) / ".config" / "fmv3d" / "sensors.json";
  return fs::path(".fmv3d-sensors.json");
}

void SensorDatabase::Load(const fs::path& path) {
  const nlohmann::json j = core::ReadJson(path);
  try {
    for (const auto& e : j.at("sensors")) Add(EntryFromJson(e, path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(path.string() + ": malformed sensor database (" + e.what() + ")");
  } catch (const Error& e) {
    throw Error(path.string() + ": " + e.what());
  }
}

SensorDatabase SensorDatabase::LoadDefault() {
  SensorDatabase db;
  const fs::path shipped = ShippedDatabasePath();
  if (!shipped.empty())
    db.Load(shipped);
  else
    spdlog::debug("no shipped sensor database found (set FMV3D_SENSOR_DB)");
  const fs::path user = UserDatabasePath();
  std::error_code ec;
  if (fs::is_regular_file(user, ec)) db.Load(user);
  return db;
}

void SensorDatabase::Add(const SensorEntry& entry) {
  for (auto& e : entries_)
    if (Lower(e.name) == Lower(entry.name)) {
      e = entry;
      return;
    }
  entries_.push_back(entry);
}

const SensorEntry* SensorDatabase::FindByName(const std::string& name) const {
  for (const auto& e : entries_)
    if (Lower(e.name) == Lower(name)) return &e;
  return nullptr;
}

const SensorEntry* SensorDatabase::FindByExif(const std::string& make, const std::string& model) const {
  if (model.empty()) return nullptr;
  const SensorEntry* hit = nullptr;
  for (const auto& e : entries_) {  // last match wins: user entries override shipped ones
    if (!e.make.empty() && !make.empty() && Lower(make).rfind(Lower(e.make), 0) != 0) continue;
    for (const auto& m : e.models)
      if (Lower(m) == Lower(model)) hit = &e;
  }
  return hit;
}

void SaveUserSensor(const fs::path& db_path, const std::string& name, const core::Camera& camera,
                    const std::string& note) {
  if (name.empty()) throw Error("--save-as: empty name");
  nlohmann::json j = {{"version", 1}, {"sensors", nlohmann::json::array()}};
  std::error_code ec;
  if (fs::is_regular_file(db_path, ec)) {
    j = core::ReadJson(db_path);
    if (!j.contains("sensors") || !j["sensors"].is_array())
      throw Error(db_path.string() + ": malformed sensor database (no \"sensors\" array)");
  }
  SensorEntry e;
  e.name = name;
  e.width = camera.width;
  e.height = camera.height;
  e.calibration = camera;
  e.note = note;
  auto& arr = j["sensors"];
  bool replaced = false;
  for (auto& x : arr)
    if (Lower(x.value("name", "")) == Lower(name)) {
      x = SensorToJson(e);
      replaced = true;
    }
  if (!replaced) arr.push_back(SensorToJson(e));
  core::WriteJson(db_path, j);
}

bool PriorFromSensor(const SensorEntry& e, int width, int height, double exif_focal_mm, core::Camera* out) {
  if (e.calibration) {
    if (ScaleCamera(*e.calibration, width, height, out)) return true;
    // A calibration of another aspect ratio (e.g. a 4:3 still vs 16:9 video): keep only the focal scaled by
    // width, like a sensor with a known focal.
    *out = core::Camera::Pinhole(
        width, height,
        e.calibration->fx() * double(std::max(width, height)) / std::max(e.calibration->width, e.calibration->height));
    return true;
  }
  const double focal = exif_focal_mm > 0 ? exif_focal_mm : e.focal_mm;
  const double long_side = std::max(width, height);
  if (focal > 0 && e.sensor_width_mm > 0) {
    // The image's long side spans the sensor's long side (video modes crop height, not width).
    *out = core::Camera::Pinhole(width, height, focal * long_side / std::max(e.sensor_width_mm, e.sensor_height_mm));
    return true;
  }
  if (e.focal_35mm > 0 && exif_focal_mm <= 0) {
    // 35 mm-equivalent focal is defined on the diagonal (43.27 mm) of the native frame; an image of another
    // aspect ratio is taken as the native frame's long side.
    double diag_px = std::hypot(width, height);
    if (e.width > 0 && e.height > 0) diag_px = long_side * std::hypot(e.width, e.height) / std::max(e.width, e.height);
    *out = core::Camera::Pinhole(width, height, e.focal_35mm * diag_px / std::hypot(36.0, 24.0));
    return true;
  }
  return false;
}

}  // namespace fmv3d::calib
