// `fmv3d calibrate --board 9x6 --square 0.025 INPUTS... -o camera.json [--save-as NAME] [--drop NAME]...`:
// chessboard calibration from images, folders of them, or calibration videos (calib/board_video.h: frames sampled,
// boards detected, a spread subset kept). Writes camera.json, camera.yaml (OpenCV), camera-distortion.png,
// camera-corners/NAME.png and, for videos, the kept frames as camera-frames/NAME.png.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "command.h"
#include "fmv3d/calib/board_video.h"
#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/chessboard.h"
#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/ingest/frames.h"
#include "fmv3d/ingest/video_reader.h"
#include "fmv3d/io/image_io.h"

namespace fmv3d::app::cmd_calibrate {
namespace {
namespace fs = std::filesystem;

struct CalibArgs {
  std::string board = "9x6";
  double square = 0.025;
  std::vector<std::string> images;
  std::string output;
  std::string save_as;
  std::vector<std::string> drop;
  calib::VideoBoardOptions video;
};

// The board views of every input: images as they are (unless dropped), videos through DetectBoardsInVideo.
// Video frames are written to frames_dir, so that they can be looked at (the console's window shows them).
void CollectViews(const CalibArgs& a, const calib::BoardSpec& board, const fs::path& frames_dir,
                  std::vector<calib::BoardDetection>* detections, std::vector<cv::Mat>* images,
                  nlohmann::json* videos) {
  const std::set<std::string> drop(a.drop.begin(), a.drop.end());
  const auto files = ingest::ExpandInputs(std::vector<fs::path>(a.images.begin(), a.images.end()));
  core::Progress progress("detect", files.size());
  for (const auto& file : files) {
    if (io::HasVideoExtension(file)) {
      calib::VideoBoardViews v = calib::DetectBoardsInVideo(file, board, a.video, drop);
      core::EnsureDirectory(frames_dir);
      for (size_t k = 0; k < v.detections.size(); ++k) {
        io::WriteImage(frames_dir / v.detections[k].name, v.images[k]);
        detections->push_back(std::move(v.detections[k]));
        images->push_back(std::move(v.images[k]));
      }
      std::printf("%s: %d frames sampled, board found in %d, %zu kept (spread)%s\n", file.filename().c_str(), v.sampled,
                  v.found, v.images.size(),
                  v.excluded.empty() ? "" : (", " + std::to_string(v.excluded.size()) + " dropped").c_str());
      videos->push_back({{"video", file.filename().string()},
                         {"sampled", v.sampled},
                         {"found", v.found},
                         {"kept", v.images.size()},
                         {"dropped", v.excluded}});
    } else if (!drop.count(file.filename().string())) {
      images->push_back(ingest::ReadInputImage(file));
      detections->push_back(calib::DetectChessboard(images->back(), board, file.filename().string()));
    }
    progress.Add();
  }
}

void Run(const CalibArgs& a) {
  const calib::BoardSpec board = calib::BoardSpec::Parse(a.board, a.square);
  const fs::path out(a.output);
  const fs::path stem = out.parent_path() / out.stem();
  const fs::path corners_dir = stem.string() + "-corners", frames_dir = stem.string() + "-frames";
  std::error_code ec;
  fs::remove_all(frames_dir, ec);  // a previous run's video frames
  core::EnsureDirectory(corners_dir);
  std::vector<calib::BoardDetection> detections;
  std::vector<cv::Mat> images;
  nlohmann::json videos = nlohmann::json::array();
  CollectViews(a, board, frames_dir, &detections, &images, &videos);
  for (size_t i = 0; i < detections.size(); ++i)
    io::WriteImage(corners_dir / (fs::path(detections[i].name).stem().string() + ".png"),
                   calib::DrawCorners(images[i], detections[i], board));
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
  if (!videos.empty()) {  // where the kept frames came from
    nlohmann::json j = core::ReadJson(out);
    j["videos"] = videos;
    j["frames_dir"] = frames_dir.filename().string();
    core::WriteJson(out, j);
  }
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
  cmd->add_option("INPUTS", a->images, "Board images, folders of them, or calibration videos")->required();
  cmd->add_option("--drop", a->drop, "Leave out this image or video frame (file name, e.g. calib-000120.png)");
  cmd->add_option("--video-samples", a->video.samples, "Videos: frames sampled evenly over each")
      ->capture_default_str();
  cmd->add_option("--max-views", a->video.max_views, "Videos: views kept per video, spread over image and pose")
      ->capture_default_str();
  cmd->add_option("-o,--output", a->output, "camera.json to write (also .yaml, -distortion.png, -corners/)")
      ->required();
  cmd->add_option("--save-as", a->save_as, "Also add the camera to your sensor database under NAME");
  cmd->callback([a] { Run(*a); });
}

const RegisterCommand reg(90, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_calibrate
