// Intrinsics priors for `fmv3d frames`, in the order of trust:
//   1. a calibration file (--camera: camera.json or OpenCV YAML), scaled to the frame size when the aspect
//      ratio matches                                                       → PriorKind::kCalibration (FILE)
//   2. the sensor database: --sensor NAME, or a match on EXIF make/model    → PriorKind::kSensorDb (NAME)
//   3. EXIF focal length with the focal-plane resolution, or the 35 mm-equivalent focal → PriorKind::kExif
//   4. f = 1.2 · max(w, h)                                                  → PriorKind::kGuess (BA must refine it)
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/ingest/frames.h"

namespace fmv3d::calib {

struct PriorOptions {
  std::filesystem::path camera_file;  // --camera
  std::string sensor_name;            // --sensor (must exist in the database)
};

class PriorChooser {
 public:
  // Reads the calibration file and checks the sensor name now, so bad options fail before any decoding.
  PriorChooser(const PriorOptions& options, SensorDatabase db);
  core::Camera Choose(const ingest::CameraGroup& group, io::PriorSource* prior_source) const;
  ingest::IntrinsicsPriorFn AsFunction() const;

 private:
  PriorOptions options_;
  SensorDatabase db_;
  std::optional<core::Camera> calibration_;
  const SensorEntry* forced_ = nullptr;
};

// Intrinsics from EXIF alone (focal + focal-plane resolution, or 35 mm equivalent); false when insufficient.
bool PriorFromExif(const io::ExifInfo& exif, int width, int height, core::Camera* out);

}  // namespace fmv3d::calib
