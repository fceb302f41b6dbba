#include "fmv3d/calib/priors.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <memory>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/core/error.h"

namespace fmv3d::calib {

bool PriorFromExif(const io::ExifInfo& exif, int width, int height, core::Camera* out) {
  if (exif.focal_mm > 0 && exif.focal_plane_x_res > 0) {
    // Focal-plane resolution refers to the full-size image (PixelXDimension) — rescale to ours.
    const double scale = exif.pixel_width > 0 ? double(width) / exif.pixel_width : 1.0;
    *out = core::Camera::Pinhole(width, height, exif.focal_mm * exif.focal_plane_x_res * scale);
    return true;
  }
  if (exif.focal_35mm > 0) {
    *out = core::Camera::Pinhole(width, height, exif.focal_35mm * std::hypot(width, height) / std::hypot(36.0, 24.0));
    return true;
  }
  return false;
}

PriorChooser::PriorChooser(const PriorOptions& options, SensorDatabase db) : options_(options), db_(std::move(db)) {
  if (!options_.camera_file.empty()) calibration_ = ReadCameraFile(options_.camera_file);
  if (!options_.sensor_name.empty()) {
    forced_ = db_.FindByName(options_.sensor_name);
    if (!forced_)
      throw Error("--sensor: '" + options_.sensor_name + "' is not in the sensor database (see `fmv3d cameras`)");
  }
}

core::Camera PriorChooser::Choose(const ingest::CameraGroup& g, io::PriorSource* source) const {
  core::Camera cam;
  if (calibration_) {
    if (ScaleCamera(*calibration_, g.width, g.height, &cam)) {
      *source = {io::PriorKind::kCalibration, options_.camera_file.string()};
      return cam;
    }
    spdlog::warn("{}: {}x{} does not have the aspect ratio of the calibration {} ({}x{}); not using it", g.source,
                 g.width, g.height, options_.camera_file.string(), calibration_->width, calibration_->height);
  }
  const SensorEntry* entry = forced_ ? forced_ : db_.FindByExif(g.exif.make, g.exif.model);
  if (entry && PriorFromSensor(*entry, g.width, g.height, g.exif.focal_mm, &cam)) {
    *source = {io::PriorKind::kSensorDb, entry->name};
    return cam;
  }
  if (PriorFromExif(g.exif, g.width, g.height, &cam)) {
    *source = {io::PriorKind::kExif, ""};
    return cam;
  }
  *source = {io::PriorKind::kGuess, ""};
  return ingest::GuessPrior(g.width, g.height);
}

ingest::IntrinsicsPriorFn PriorChooser::AsFunction() const {
  auto self = std::make_shared<PriorChooser>(*this);
  // forced_ points into db_: re-resolve it in the copy.
  if (!options_.sensor_name.empty()) self->forced_ = self->db_.FindByName(options_.sensor_name);
  return [self](const ingest::CameraGroup& g, io::PriorSource* source) { return self->Choose(g, source); };
}

}  // namespace fmv3d::calib
