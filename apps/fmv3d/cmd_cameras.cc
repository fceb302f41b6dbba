// `fmv3d cameras`: lists the sensor database (shipped entries and the user's calibrated cameras).
#include <cstdio>
#include <memory>

#include "command.h"
#include "fmv3d/calib/sensor_db.h"

namespace fmv3d::app::cmd_cameras {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("cameras", "List the sensor database (known cameras and your calibrations)");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "Print the database as JSON");
  cmd->callback([json] {
    const auto db = calib::SensorDatabase::LoadDefault();
    if (*json) {
      nlohmann::json j = {{"version", 1}, {"sensors", nlohmann::json::array()}};
      for (const auto& e : db.entries()) {
        auto ej = calib::SensorToJson(e);
        ej["origin"] = e.origin;
        j["sensors"].push_back(ej);
      }
      std::printf("%s\n", j.dump(2).c_str());
      return;
    }
    std::printf("shipped: %s\nuser:    %s\n\n", calib::ShippedDatabasePath().c_str(),
                calib::UserDatabasePath().c_str());
    std::printf("%-34s %-12s %-22s %-13s %-9s %-7s %s\n", "name", "make", "EXIF model", "sensor mm", "focal mm",
                "35mm eq", "resolution / calibration");
    for (const auto& e : db.entries()) {
      char sensor[32] = "-", focal[16] = "-", f35[16] = "-", res[96] = "-";
      if (e.sensor_width_mm > 0)
        std::snprintf(sensor, sizeof(sensor), "%.2fx%.2f", e.sensor_width_mm, e.sensor_height_mm);
      if (e.focal_mm > 0) std::snprintf(focal, sizeof(focal), "%.2f", e.focal_mm);
      if (e.focal_35mm > 0) std::snprintf(f35, sizeof(f35), "%.0f", e.focal_35mm);
      if (e.calibration)
        std::snprintf(res, sizeof(res), "%dx%d calibrated f=%.1f px k1=%.4f", e.calibration->width,
                      e.calibration->height, e.calibration->f, e.calibration->k1);
      else if (e.width > 0)
        std::snprintf(res, sizeof(res), "%dx%d", e.width, e.height);
      std::string models;
      for (const auto& m : e.models) models += (models.empty() ? "" : ",") + m;
      std::printf("%-34s %-12s %-22s %-13s %-9s %-7s %s\n", e.name.c_str(), e.make.empty() ? "-" : e.make.c_str(),
                  models.empty() ? "-" : models.c_str(), sensor, focal, f35, res);
    }
  });
}

const RegisterCommand reg(95, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_cameras
