#include "fmv3d/calib/sensor_db.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/priors.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/frames_index.h"
#include "io/image_test_util.h"
#include "test_util.h"

namespace fmv3d::calib {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

TEST(SensorDb, ShippedDatabaseLoadsAndMatchesExif) {
  const fs::path shipped = ShippedDatabasePath();
  ASSERT_FALSE(shipped.empty());
  SensorDatabase db;
  db.Load(shipped);
  ASSERT_GE(db.entries().size(), 10u);
  std::set<std::string> names;
  for (const auto& e : db.entries()) {
    EXPECT_TRUE(names.insert(e.name).second) << "duplicate " << e.name;
    EXPECT_GT(e.width, 0) << e.name;
    EXPECT_TRUE(e.sensor_width_mm > 0 || e.focal_35mm > 0) << e.name;
    if (e.sensor_width_mm > 0 && e.width > 0) {  // sensor and pixel aspect ratios agree (4:3 vs 1/2.3")
      EXPECT_NEAR(e.sensor_width_mm / e.sensor_height_mm, double(e.width) / e.height, 0.06) << e.name;
    }
  }
  const SensorEntry* p4p = db.FindByExif("DJI", "FC6310");
  ASSERT_NE(p4p, nullptr);
  EXPECT_EQ(p4p->name, "DJI Phantom 4 Pro");
  EXPECT_EQ(db.FindByExif("dji", "fc6310"), p4p);        // case-insensitive
  EXPECT_EQ(db.FindByExif("Canon", "FC6310"), nullptr);  // wrong make
  EXPECT_EQ(db.FindByName("dji phantom 4 pro"), p4p);
  EXPECT_EQ(db.FindByExif("DJI", ""), nullptr);

  // f = focal · image width / sensor width: 8.8 mm on 13.2 mm over 5472 px = 3648 px, at any same-aspect size.
  core::Camera c;
  ASSERT_TRUE(PriorFromSensor(*p4p, 5472, 3648, 0, &c));
  EXPECT_NEAR(c.f, 3648, 1e-9);
  ASSERT_TRUE(PriorFromSensor(*p4p, 1368, 912, 0, &c));
  EXPECT_NEAR(c.f, 912, 1e-9);
  EXPECT_DOUBLE_EQ(c.u0, 684);
  // A 35 mm-equivalent-only entry: 24 mm on the 43.27 mm diagonal.
  const SensorEntry* mavic3 = db.FindByName("DJI Mavic 3");
  ASSERT_NE(mavic3, nullptr);
  ASSERT_TRUE(PriorFromSensor(*mavic3, 5280, 3956, 0, &c));
  EXPECT_NEAR(c.f, 24 * std::hypot(5280, 3956) / std::hypot(36, 24), 1e-6);
  // A zoom lens entry without focal: only with the EXIF focal.
  const SensorEntry* rx100 = db.FindByName("Sony RX100");
  ASSERT_NE(rx100, nullptr);
  EXPECT_FALSE(PriorFromSensor(*rx100, 5472, 3648, 0, &c));
  ASSERT_TRUE(PriorFromSensor(*rx100, 5472, 3648, 10.4, &c));
  EXPECT_NEAR(c.f, 10.4 * 5472 / 13.2, 1e-9);
}

TEST(SensorDb, UserEntriesOverrideAndRoundTrip) {
  TempDir tmp("fmv3d-sensors");
  core::Camera cam = core::Camera::Pinhole(640, 480, 533.7);
  cam.aspect = 0.9998;
  cam.u0 = 342.7;
  cam.v0 = 234.6;
  cam.k1 = -0.289;
  cam.k2 = 0.098;
  const fs::path user = tmp / "user.json";
  SaveUserSensor(user, "bench cam", cam, "test");
  SaveUserSensor(user, "Bench Cam", cam, "replaced");  // same name, case-insensitive: replaced, not added
  SensorDatabase db;
  db.Load(user);
  ASSERT_EQ(db.entries().size(), 1u);
  const SensorEntry* e = db.FindByName("BENCH CAM");
  ASSERT_NE(e, nullptr);
  ASSERT_TRUE(e->calibration.has_value());
  EXPECT_DOUBLE_EQ(e->calibration->k1, -0.289);
  EXPECT_EQ(e->note, "replaced");
  // A calibration scales to another size of the same aspect ratio.
  core::Camera half;
  ASSERT_TRUE(PriorFromSensor(*e, 320, 240, 0, &half));
  EXPECT_NEAR(half.f, 533.7 / 2, 1e-9);
  EXPECT_NEAR(half.u0, 342.7 / 2, 1e-9);
  EXPECT_DOUBLE_EQ(half.k1, -0.289);
  // Malformed database: error naming the file.
  std::ofstream(tmp / "bad.json") << "{\"sensors\": [{\"make\": \"x\"}]}";
  try {
    db.Load(tmp / "bad.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
  }
}

TEST(CameraFile, JsonAndOpenCvYamlRoundTrip) {
  TempDir tmp("fmv3d-camfile");
  CalibrationResult r;
  r.camera = core::Camera::Pinhole(1280, 720, 1000);
  r.camera.aspect = 1.001;
  r.camera.u0 = 641.2;
  r.camera.v0 = 359.1;
  r.camera.k1 = -0.1;
  r.camera.k2 = 0.02;
  r.camera.p1 = 0.001;
  r.camera.p2 = -0.002;
  r.rms = 0.2;
  WriteCameraJson(tmp / "camera.json", r);
  WriteOpenCvYaml(tmp / "camera.yaml", r.camera, r.rms);
  for (const char* name : {"camera.json", "camera.yaml"}) {
    const core::Camera c = ReadCameraFile(tmp / name);
    EXPECT_EQ(c.width, 1280) << name;
    EXPECT_NEAR(c.f, 1000, 1e-9) << name;
    EXPECT_NEAR(c.aspect, 1.001, 1e-12) << name;
    EXPECT_NEAR(c.u0, 641.2, 1e-9) << name;
    EXPECT_NEAR(c.v0, 359.1, 1e-9) << name;
    EXPECT_NEAR(c.k1, -0.1, 1e-12) << name;
    EXPECT_NEAR(c.p2, -0.002, 1e-12) << name;
  }
  // OpenCV's cx is ours − 0.5.
  cv::FileStorage fsr((tmp / "camera.yaml").string(), cv::FileStorage::READ);
  cv::Mat K;
  fsr["camera_matrix"] >> K;
  EXPECT_NEAR(K.at<double>(0, 2), 640.7, 1e-9);
  // k3 cannot be represented: refused with the file's name.
  {
    cv::FileStorage fsw((tmp / "k3.yaml").string(), cv::FileStorage::WRITE);
    fsw << "image_width" << 640 << "image_height" << 480 << "camera_matrix"
        << cv::Mat(cv::Matx33d(500, 0, 320, 0, 500, 240, 0, 0, 1)) << "distortion_coefficients"
        << cv::Mat(cv::Matx<double, 1, 5>(-0.1, 0.01, 0, 0, 0.003));
  }
  EXPECT_THROW(ReadCameraFile(tmp / "k3.yaml"), Error);
  EXPECT_THROW(ReadCameraFile(tmp / "missing.json"), Error);
  core::Camera scaled;
  EXPECT_FALSE(ScaleCamera(r.camera, 640, 480, &scaled));  // 16:9 → 4:3
  ASSERT_TRUE(ScaleCamera(r.camera, 640, 360, &scaled));
  EXPECT_NEAR(scaled.f, 500, 1e-9);
  EXPECT_NEAR(scaled.u0, 320.6, 1e-9);
}

TEST(Priors, OrderOfTrust) {
  TempDir tmp("fmv3d-priors");
  CalibrationResult r;
  r.camera = core::Camera::Pinhole(1368, 912, 950);
  WriteCameraJson(tmp / "camera.json", r);
  SensorDatabase db;
  db.Load(ShippedDatabasePath());
  ingest::CameraGroup g;
  g.width = 1368;
  g.height = 912;
  g.exif.make = "DJI";
  g.exif.model = "FC6310";
  g.exif.focal_mm = 8.8;
  fmv3d::io::PriorSource source;
  // 1. calibration file
  EXPECT_NEAR(PriorChooser({tmp / "camera.json", ""}, db).Choose(g, &source).f, 950, 1e-9);
  EXPECT_EQ(fmv3d::io::PriorSourceName(source), "calibration:" + (tmp / "camera.json").string());
  // ... not for frames of another aspect ratio: falls through to the sensor database.
  ingest::CameraGroup square = g;
  square.width = square.height = 912;
  PriorChooser({tmp / "camera.json", ""}, db).Choose(square, &source);
  EXPECT_EQ(fmv3d::io::PriorSourceName(source), "sensor-db:DJI Phantom 4 Pro");
  // 2. sensor database by EXIF model
  EXPECT_NEAR(PriorChooser({}, db).Choose(g, &source).f, 912, 1e-9);
  EXPECT_EQ(fmv3d::io::PriorSourceName(source), "sensor-db:DJI Phantom 4 Pro");
  // ... or forced with --sensor, for a video without EXIF
  ingest::CameraGroup video;
  video.width = 1368;
  video.height = 912;
  video.is_video = true;
  EXPECT_NEAR(PriorChooser({"", "DJI Phantom 4 Pro"}, db).Choose(video, &source).f, 912, 1e-9);
  EXPECT_THROW(PriorChooser({"", "No Such Camera"}, db), Error);
  // 3. EXIF alone: 35 mm equivalent
  ingest::CameraGroup unknown = g;
  unknown.exif.model = "Unknown-1";
  unknown.exif.focal_35mm = 28;
  EXPECT_NEAR(PriorChooser({}, db).Choose(unknown, &source).f, 28 * std::hypot(1368, 912) / std::hypot(36, 24), 1e-9);
  EXPECT_EQ(fmv3d::io::PriorSourceName(source), "exif");
  // 4. guess
  EXPECT_NEAR(PriorChooser({}, db).Choose(video, &source).f, 1.2 * 1368, 1e-9);
  EXPECT_EQ(fmv3d::io::PriorSourceName(source), "guess");
}

// The three commands end to end, as a user runs them.
TEST(CalibCli, CalibrateSaveAsCamerasAndFramesWithPriors) {
  FMV3D_REQUIRE_SHARED_DATA("calib/opencv-chessboard/left01.jpg");
  TempDir tmp("fmv3d-calib-cli");
  setenv("FMV3D_USER_SENSORS", (tmp / "user-sensors.json").c_str(), 1);
  const auto boards = test::SharedData() / "calib/opencv-chessboard";
  auto r = test::RunCli("calibrate --board 9x6 --square 0.025 '" + boards.string() + "' -o '" +
                        (tmp / "out" / "camera.json").string() + "' --save-as 'lab cam'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("overall RMS"), std::string::npos);
  for (const char* f : {"camera.json", "camera.yaml", "camera-distortion.png", "camera-corners/left01.png"})
    EXPECT_TRUE(fs::exists(tmp / "out" / f)) << f;
  const auto j = core::ReadJson(tmp / "out" / "camera.json");
  EXPECT_EQ(j["images"].size(), 13u);
  EXPECT_LT(j["rms"].get<double>(), 0.5);

  r = test::RunCli("cameras");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("lab cam"), std::string::npos);
  EXPECT_NE(r.out.find("DJI Phantom 4 Pro"), std::string::npos);

  // frames with --camera (the calibrated 640x480 camera) and with the saved sensor by name.
  r = test::RunCli("frames '" + (boards / "left01.jpg").string() + "' -o '" + (tmp / "ws1").string() + "' --camera '" +
                   (tmp / "out" / "camera.json").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto index = io::ReadFramesIndex(tmp / "ws1" / "frames" / "frames.json");
  ASSERT_EQ(index.cameras.size(), 1u);
  EXPECT_EQ(index.cameras[0].prior_source.kind, fmv3d::io::PriorKind::kCalibration)
      << fmv3d::io::PriorSourceName(index.cameras[0].prior_source);
  EXPECT_NEAR(index.cameras[0].camera.f, j["f"].get<double>(), 1e-9);
  EXPECT_NEAR(index.cameras[0].camera.k1, j["k1"].get<double>(), 1e-12);

  r = test::RunCli("frames '" + (boards / "left02.jpg").string() + "' -o '" + (tmp / "ws2").string() +
                   "' --sensor 'lab cam'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  index = io::ReadFramesIndex(tmp / "ws2" / "frames" / "frames.json");
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras[0].prior_source), "sensor-db:lab cam");
  EXPECT_NEAR(index.cameras[0].camera.f, j["f"].get<double>(), 1e-9);

  // Usage and input errors: non-zero exit and a message naming the problem.
  r = test::RunCli("calibrate --board 9by6 '" + boards.string() + "' -o '" + (tmp / "x.json").string() + "'");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("9by6"), std::string::npos) << r.err;
  r = test::RunCli("frames '" + (tmp / "nothing.mp4").string() + "' -o '" + (tmp / "ws3").string() + "'");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("nothing.mp4"), std::string::npos) << r.err;
  r = test::RunCli("frames '" + (boards / "left02.jpg").string() + "' -o '" + (tmp / "ws4").string() +
                   "' --sensor 'no such camera'");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("no such camera"), std::string::npos) << r.err;
  unsetenv("FMV3D_USER_SENSORS");
}

}  // namespace
}  // namespace fmv3d::calib

namespace fmv3d::calib {
namespace {

TEST(Priors, ExifJpegMatchesSensorDatabaseThroughIngestion) {
  // A 1368x912 JPEG whose EXIF says DJI FC6310 (Phantom 4 Pro): 8.8 mm on a 13.2 mm wide sensor → 912 px;
  // a second image without EXIF of the same size is a different camera with a guessed focal.
  TempDir tmp("fmv3d-exif-ingest");
  const cv::Mat img(912, 1368, CV_8UC3, cv::Scalar(90, 120, 150));
  cv::imwrite((tmp / "dji.jpg").string(), img);
  test::AddExifToJpeg(tmp / "dji.jpg", test::MakeExif("DJI", "FC6310", 88, 10, 24));
  cv::imwrite((tmp / "plain.jpg").string(), img);
  ingest::IngestOptions opt;
  opt.workspace = tmp / "ws";
  opt.prior = PriorChooser({}, SensorDatabase::LoadDefault()).AsFunction();
  const io::FramesIndex index = ingest::IngestFrames({tmp / "dji.jpg", tmp / "plain.jpg"}, opt);
  ASSERT_EQ(index.cameras.size(), 2u);
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras[0].prior_source), "sensor-db:DJI Phantom 4 Pro");
  EXPECT_NEAR(index.cameras[0].camera.f, 912, 1e-9);
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras[1].prior_source), "guess");
  EXPECT_NEAR(index.cameras[1].camera.f, 1.2 * 1368, 1e-9);
  // The JPEG is copied byte for byte (EXIF kept).
  EXPECT_EQ(io::ReadExif(tmp / "ws" / "frames" / "dji.jpg").model, "FC6310");
}

}  // namespace
}  // namespace fmv3d::calib
