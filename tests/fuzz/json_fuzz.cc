// libFuzzer target for the JSON files a workspace or a user hands us: frames/frames.json, project.json (read
// into the report), camera.json / OpenCV YAML calibrations (`--camera`), the sensor database, telemetry tracks
// and geo/georef.json. The same bytes go to every reader; each must return a value or throw fmv3d::Error
// (a nlohmann::json exception escaping is a finding: the user would get a library message, not ours).
#include <cstddef>
#include <cstdint>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/telemetry.h"
#include "fmv3d/pipeline/report.h"
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
  // georef.json and project.json are read from a workspace folder.
  const auto ws = fuzz::ScratchDir() / "ws";
  core::EnsureDirectory(ws / "geo");
  fuzz::WriteScratch("ws/geo/georef.json", bytes, size);
  try {
    (void)geo::ReadGeoref(ws);
  } catch (const Error&) {
  }
  fuzz::WriteScratch("ws/project.json", bytes, size);
  try {
    (void)pipeline::WriteReport(ws);
  } catch (const Error&) {
  }
  return 0;
}
