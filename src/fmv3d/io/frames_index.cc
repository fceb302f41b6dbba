#include "fmv3d/io/frames_index.h"

#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::io {

namespace {
constexpr char kSensorDbPrefix[] = "sensor-db:";
constexpr char kCalibrationPrefix[] = "calibration:";
}  // namespace

std::string PriorSourceName(const PriorSource& s) {
  switch (s.kind) {
    case PriorKind::kNone:
      return "";
    case PriorKind::kGuess:
      return "guess";
    case PriorKind::kExif:
      return "exif";
    case PriorKind::kSensorDb:
      return kSensorDbPrefix + s.detail;
    case PriorKind::kCalibration:
      return kCalibrationPrefix + s.detail;
    case PriorKind::kTelemetryHfov:
      return "telemetry-hfov";
    case PriorKind::kOther:
      return s.detail;
  }
  return s.detail;
}

PriorSource ParsePriorSource(const std::string& name) {
  const auto with_prefix = [&name](const char* prefix) { return name.rfind(prefix, 0) == 0; };
  if (name.empty()) return {PriorKind::kNone, ""};
  if (name == "guess") return {PriorKind::kGuess, ""};
  if (name == "exif") return {PriorKind::kExif, ""};
  if (name == "telemetry-hfov") return {PriorKind::kTelemetryHfov, ""};
  if (with_prefix(kSensorDbPrefix)) return {PriorKind::kSensorDb, name.substr(sizeof(kSensorDbPrefix) - 1)};
  if (with_prefix(kCalibrationPrefix)) return {PriorKind::kCalibration, name.substr(sizeof(kCalibrationPrefix) - 1)};
  return {PriorKind::kOther, name};
}

const CameraPrior* FramesIndex::FindCamera(uint32_t id) const {
  for (const auto& c : cameras)
    if (c.camera.id == id) return &c;
  return nullptr;
}

void WriteFramesIndex(const FramesIndex& index, const std::filesystem::path& path) {
  nlohmann::json j;
  j["version"] = 1;
  j["cameras"] = nlohmann::json::array();
  for (const auto& c : index.cameras) {
    const auto& k = c.camera;
    j["cameras"].push_back({{"id", k.id},
                            {"width", k.width},
                            {"height", k.height},
                            {"prior", core::IntrinsicsToJson(k)},
                            {"prior_source", PriorSourceName(c.prior_source)},
                            {"source", c.source}});
  }
  j["frames"] = nlohmann::json::array();
  for (const auto& f : index.frames) {
    nlohmann::json fj = {{"name", f.name},           {"camera_id", f.camera_id},
                         {"source", f.source},       {"frame_index", f.frame_index},
                         {"timestamp", f.timestamp}, {"sharpness", f.sharpness}};
    if (f.telemetry) fj["telemetry"] = core::ToJson(*f.telemetry);
    j["frames"].push_back(fj);
  }
  core::WriteJson(path, j);
}

FramesIndex ReadFramesIndex(const std::filesystem::path& path) {
  const nlohmann::json j = core::ReadJson(path);
  FramesIndex index;
  try {
    for (const auto& cj : j.at("cameras")) {
      CameraPrior c;
      c.camera.id = cj.at("id").get<uint32_t>();
      c.camera.width = cj.at("width").get<int>();
      c.camera.height = cj.at("height").get<int>();
      const auto& p = cj.at("prior");
      core::IntrinsicsFromJson(p, &c.camera);
      c.prior_source = ParsePriorSource(cj.value("prior_source", ""));
      c.source = cj.value("source", "");
      c.camera.Validate();
      index.cameras.push_back(c);
    }
    for (const auto& fj : j.at("frames")) {
      FrameRecord f;
      f.name = fj.at("name").get<std::string>();
      f.camera_id = fj.at("camera_id").get<uint32_t>();
      f.source = fj.value("source", "");
      f.frame_index = fj.value("frame_index", int64_t{0});
      f.timestamp = fj.value("timestamp", 0.0);
      f.sharpness = fj.value("sharpness", 0.0);
      if (fj.contains("telemetry") && !fj["telemetry"].is_null()) {
        nlohmann::json t = fj["telemetry"];
        if (t.is_object() && !t.contains("time")) t["time"] = f.timestamp;
        try {
          f.telemetry = core::TelemetryFromJson(t);
        } catch (const Error& e) {
          throw Error("frame " + f.name + ": " + e.what());
        }
      }
      index.frames.push_back(f);
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(path.string() + ": malformed frames index (" + e.what() + ")");
  } catch (const Error& e) {
    throw Error(path.string() + ": " + e.what());
  }
  for (const auto& f : index.frames)
    if (!index.FindCamera(f.camera_id))
      throw Error(path.string() + ": frame " + f.name + " refers to missing camera " + std::to_string(f.camera_id));
  return index;
}

}  // namespace fmv3d::io
