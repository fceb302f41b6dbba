// `fmv3d calibrate --board 9x6 --square 0.025 IMAGES... -o camera.json [--save-as NAME]`: chessboard
// calibration. Writes camera.json, camera.yaml (OpenCV), camera-distortion.png and camera-corners/NAME.png.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>

#include "command.h"
#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/chessboard.h"
#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/ingest/frames.h"
#include "fmv3d/ingest/video_reader.h"
#include "fmv3d/io/image_io.h"

namespace fmv3d::app {
namespace {
namespace fs = std::filesystem;

struct CalibArgs {
  std::string board = "9x6";
  double square = 0.025;
  std::vector<std::string> images;
  std::string output;
  std::string save_as;
};

void Run(const CalibArgs& a) {
  const calib::BoardSpec board = calib::BoardSpec::Parse(a.board, a.square);
  const auto files = ingest::ExpandInputs(std::vector<fs::path>(a.images.begin(), a.images.end()));
  const fs::path out(a.output);
  const fs::path stem = out.parent_path() / out.stem();
  const fs::path corners_dir = stem.string() + "-corners";
  core::EnsureDirectory(corners_dir);

  std::vector<calib::BoardDetection> detections(files.size());
  {
    core::Progress progress("detect", files.size());
    for (size_t i = 0; i < files.size(); ++i) {
      const cv::Mat img = ingest::ReadInputImage(files[i]);
      detections[i] = calib::DetectChessboard(img, board, files[i].filename().string());
      io::WriteImage(corners_dir / (files[i].stem().string() + ".png"), calib::DrawCorners(img, detections[i], board));
      progress.Add();
    }
  }
  const calib::CalibrationResult r = calib::Calibrate(detections, board);
  std::printf("%-28s %s\n", "image", "RMS px");
  for (size_t i = 0; i < r.used.size(); ++i) std::printf("%-28s %.4f\n", r.used[i].c_str(), r.per_image_rms[i]);
  for (const auto& n : r.rejected) std::printf("%-28s rejected: board not found\n", n.c_str());
  std::printf("overall RMS: %.4f px over %zu images (%zu rejected)\n", r.rms, r.used.size(), r.rejected.size());
  const auto& c = r.camera;
  const auto& s = r.stddev;
  std::printf("size   %d x %d\n", c.width, c.height);
  std::printf("f      %12.4f  +- %.4f px\n", c.f, s[core::kF]);
  std::printf("s_u    %12.6f  +- %.6f\n", c.aspect, s[core::kAspect]);
  std::printf("u0     %12.4f  +- %.4f px  (pixel centres at +0.5)\n", c.u0, s[core::kU0]);
  std::printf("v0     %12.4f  +- %.4f px\n", c.v0, s[core::kV0]);
  std::printf("k1     %12.6f  +- %.6f\n", c.k1, s[core::kK1]);
  std::printf("k2     %12.6f  +- %.6f\n", c.k2, s[core::kK2]);
  std::printf("p1     %12.6f  +- %.6f\n", c.p1, s[core::kP1]);
  std::printf("p2     %12.6f  +- %.6f\n", c.p2, s[core::kP2]);

  calib::WriteCameraJson(out, r);
  const fs::path yaml = stem.string() + ".yaml";
  calib::WriteOpenCvYaml(yaml, c, r.rms);
  const fs::path field = stem.string() + "-distortion.png";
  io::WriteImage(field, calib::DrawDistortionField(c, 10));
  std::printf("wrote %s, %s, %s, %s/\n", out.c_str(), yaml.c_str(), field.c_str(), corners_dir.c_str());
  if (!a.save_as.empty()) {
    const fs::path db = calib::UserDatabasePath();
    char note[128];
    std::snprintf(note, sizeof(note), "chessboard calibration, %zu images, RMS %.3f px", r.used.size(), r.rms);
    calib::SaveUserSensor(db, a.save_as, c, note);
    std::printf("saved as '%s' in %s\n", a.save_as.c_str(), db.c_str());
  }
}

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("calibrate", "Chessboard calibration: f, s_u, u0, v0, k1, k2, p1, p2");
  auto a = std::make_shared<CalibArgs>();
  cmd->add_option("--board", a->board, "Inner corners COLSxROWS")->capture_default_str();
  cmd->add_option("--square", a->square, "Square side in metres")->capture_default_str();
  cmd->add_option("IMAGES", a->images, "Board images or folders")->required();
  cmd->add_option("-o,--output", a->output, "camera.json to write (also .yaml, -distortion.png, -corners/)")
      ->required();
  cmd->add_option("--save-as", a->save_as, "Also add the camera to your sensor database under NAME");
  cmd->callback([a] { Run(*a); });
}

const RegisterCommand reg(90, Add);

}  // namespace
}  // namespace fmv3d::app
