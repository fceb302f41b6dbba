// Sensor database: known imaging systems (shipped data/sensors.json) plus the user's own calibrated cameras
// (added by `fmv3d calibrate ... --save-as NAME`), used for intrinsics priors and listed by `fmv3d cameras`.
//
// Where the files are:
//   shipped: $FMV3D_SENSOR_DB, else <exe dir>/../share/fmv3d/sensors.json, <exe dir>/../data/sensors.json,
//            or the source tree's data/sensors.json (development builds).
//   user:    $FMV3D_USER_SENSORS, else $XDG_CONFIG_HOME/fmv3d/sensors.json, else ~/.config/fmv3d/sensors.json.
// Both have the same format: { "version": 1, "sensors": [ entry, ... ] }, an entry as in SensorEntry.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"

namespace fmv3d::calib {

struct SensorEntry {
  std::string name;                 // unique, matched case-insensitively by --sensor
  std::string make;                 // EXIF Make (case-insensitive prefix match)
  std::vector<std::string> models;  // EXIF Model strings (case-insensitive exact match)
  double sensor_width_mm = 0, sensor_height_mm = 0;
  double focal_mm = 0;                      // fixed lens; 0 for zoom/interchangeable lenses
  double focal_35mm = 0;                    // 35 mm-equivalent focal (diagonal based)
  int width = 0, height = 0;                // native resolution
  std::optional<core::Camera> calibration;  // full intrinsics at calibration.width × height (user entries)
  std::string note;
  std::string origin;  // the file it was read from
};

class SensorDatabase {
 public:
  // Shipped + user database (each optional: missing files are skipped with a debug message; malformed
  // files throw fmv3d::Error naming them).
  static SensorDatabase LoadDefault();
  // Appends the entries of one file; throws fmv3d::Error naming the file when it is malformed.
  void Load(const std::filesystem::path& path);
  const std::vector<SensorEntry>& entries() const { return entries_; }
  const SensorEntry* FindByName(const std::string& name) const;
  const SensorEntry* FindByExif(const std::string& make, const std::string& model) const;
  // Later entries (user) override earlier ones (shipped) with the same name.
  void Add(const SensorEntry& entry);

 private:
  std::vector<SensorEntry> entries_;
};

std::filesystem::path ShippedDatabasePath();  // empty when not found
std::filesystem::path UserDatabasePath();

// Adds (or replaces, by name) a calibrated camera in the user database file (atomic write).
void SaveUserSensor(const std::filesystem::path& db_path, const std::string& name, const core::Camera& camera,
                    const std::string& note);

// Intrinsics from an entry for an image of width × height; exif_focal_mm overrides the entry's focal when
// > 0 (zoom lenses). Returns false when the entry cannot give a focal length for this image.
bool PriorFromSensor(const SensorEntry& entry, int width, int height, double exif_focal_mm, core::Camera* out);

nlohmann::json SensorToJson(const SensorEntry& e);

}  // namespace fmv3d::calib
