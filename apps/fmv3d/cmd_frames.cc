// `fmv3d frames INPUT... -o WS`: images, folders and videos → WS/frames/ (keyframes + frames.json).
#include <spdlog/spdlog.h>

#include <memory>

#include "command.h"
#include "fmv3d/calib/priors.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/ingest/frames.h"

namespace fmv3d::app::cmd_frames {
namespace {

struct FramesArgs {
  std::vector<std::string> inputs;
  std::string workspace;
  std::string camera_file, sensor;
  std::string altitude_datum = "auto";
  ingest::IngestOptions options;
};

void Add(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("frames", "Ingest images/folders/videos: keyframes and intrinsics priors into WS/frames");
  auto a = std::make_shared<FramesArgs>();
  cmd->add_option("INPUT", a->inputs, "Image files, image folders, videos (any mix)")->required();
  cmd->add_option("-o,--output", a->workspace, "Workspace folder")->required();
  cmd->add_option("--max-frames", a->options.max_frames, "At most N frames in total, chosen evenly (0 = no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--min-gap", a->options.keyframes.min_gap, "Min frames between video keyframes (0 = 0.4 s)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-gap", a->options.keyframes.max_gap, "Max frames between video keyframes (0 = 1 s)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--min-motion", a->options.keyframes.min_motion,
                  "Keyframe when tracks moved this fraction of the image size");
  cmd->add_option("--camera", a->camera_file, "Calibration file (camera.json from `fmv3d calibrate`, or OpenCV YAML)");
  cmd->add_option("--sensor", a->sensor, "Sensor database entry for all inputs (see `fmv3d cameras`)");
  cmd->add_flag("--all-frames", a->options.keyframes.all_frames, "Keep every decoded video frame");
  cmd->add_option("--altitude-datum", a->altitude_datum,
                  "Datum of photo EXIF/XMP altitudes: auto (mean sea level, as EXIF and DJI define them), msl, "
                  "ellipsoid")
      ->check(CLI::IsMember({"auto", "msl", "ellipsoid"}))
      ->capture_default_str();
  cmd->add_option("--max-dop", a->options.telemetry.fix.max_dop, "Drop GPS fixes with a larger DOP")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--max-accuracy", a->options.telemetry.fix.max_horizontal_accuracy,
                  "Drop GPS fixes stating a worse horizontal accuracy, metres")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->callback([a] {
    a->options.workspace = a->workspace;
    a->options.telemetry.altitude_datum = telemetry::ParseAltitudeDatum(a->altitude_datum);
    calib::PriorOptions po;
    po.camera_file = a->camera_file;
    po.sensor_name = a->sensor;
    const calib::PriorChooser chooser(po, calib::SensorDatabase::LoadDefault());
    a->options.prior = chooser.AsFunction();
    std::vector<std::filesystem::path> inputs(a->inputs.begin(), a->inputs.end());
    const io::FramesIndex index = ingest::IngestFrames(inputs, a->options);
    std::printf("%zu frames, %zu cameras -> %s\n", index.frames.size(), index.cameras.size(),
                core::Workspace(a->workspace).frames_json().c_str());
  });
}

const RegisterCommand reg(100, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_frames
