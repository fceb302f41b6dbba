// libFuzzer target for the JSON files a workspace or a user hands us: frames/frames.json, project.json and the
// stage summaries (core::ReadJson, as the report reads them), camera.json calibrations (`--camera`), the sensor
// database and telemetry tracks. The same bytes go to every reader; each must return a value or throw fmv3d::Error
// (a nlohmann::json exception escaping is a finding: the user would get a library message, not ours).
#include <cstddef>
#include <cstdint>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/telemetry.h"
// fuzz-sources: core/camera_json.cc core/camera.cc
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d;
  const char* bytes = reinterpret_cast<const char*>(data);
  const auto json = fuzz::WriteScratch("in.json", bytes, size);
  try {
    const auto index = io::ReadFramesIndex(json);
    for (const auto& f : index.frames) (void)index.FindCamera(f.camera_id);
  } catch (const Error&) {
  }
  try {
    (void)calib::ReadCameraFile(json);
  } catch (const Error&) {
  }
  try {
    calib::SensorDatabase db;
    db.Load(json);
  } catch (const Error&) {
  }
  try {
    (void)telemetry::ReadTelemetryTracks(json);
  } catch (const Error&) {
  }
  try {
    (void)core::ReadJson(json);
  } catch (const Error&) {
  }
  return 0;
}
