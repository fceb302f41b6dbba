#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <regex>

#include "fmv3d/core/error.h"
#include "fmv3d/ingest/frames.h"
#include "test_util.h"
#include "video_test_util.h"

namespace fmv3d::ingest {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

// A folder with 3 PNGs (200x150) and 2 JPGs (160x120), and a 90-frame odd-sized MJPEG video that pans.
struct MixedInputs {
  TempDir tmp{"fmv3d-ingest"};
  fs::path images = tmp / "imgs", video = tmp / "flight.avi";
  cv::Mat tex = test::RandomTexture(1600, 600, 31);
  MixedInputs() {
    fs::create_directories(images);
    for (int i = 0; i < 3; ++i)
      cv::imwrite((images / ("img" + std::to_string(i) + ".png")).string(),
                  test::ViewOf(tex, {200, 150}, 200 + 40 * i, 300));
    for (int i = 0; i < 2; ++i)
      cv::imwrite((images / ("small" + std::to_string(i) + ".jpg")).string(),
                  test::ViewOf(tex, {160, 120}, 300 + 40 * i, 300));
    std::ofstream(images / "notes.txt") << "ignored: not an image";
    test::EncodeVideo(
        video, 90, 30,
        [&](int i) {
          return test::ViewOf(tex, {343, 259}, 300 + 4.0 * i, 300);
        },
        "mjpeg");
  }
};

TEST(FramesIngest, MixedImagesAndVideo) {
  MixedInputs in;
  IngestOptions opt;
  opt.workspace = in.tmp / "ws";
  const io::FramesIndex index = IngestFrames({in.images, in.video}, opt);
  ASSERT_EQ(index.cameras.size(), 3u);  // PNG size, JPG size, the video
  EXPECT_EQ(index.cameras[0].camera.width, 200);
  EXPECT_EQ(index.cameras[1].camera.width, 160);
  EXPECT_EQ(index.cameras[2].camera.width, 343);
  EXPECT_EQ(index.cameras[2].camera.height, 259);
  for (const auto& c : index.cameras) {
    EXPECT_EQ(fmv3d::io::PriorSourceName(c.prior_source), "guess");
    EXPECT_DOUBLE_EQ(c.camera.f, 1.2 * std::max(c.camera.width, c.camera.height));
    EXPECT_DOUBLE_EQ(c.camera.u0, c.camera.width / 2.0);
  }
  // Images first (sorted by name), keeping their names; then the video keyframes.
  ASSERT_GT(index.frames.size(), 5u + 3u);
  EXPECT_EQ(index.frames[0].name, "img0.png");
  EXPECT_EQ(index.frames[3].name, "small0.jpg");
  EXPECT_EQ(index.frames[3].camera_id, 2u);
  const std::regex video_name("flight-[0-9]{6}\\.png");
  int64_t last = -1;
  for (size_t i = 5; i < index.frames.size(); ++i) {
    const auto& f = index.frames[i];
    EXPECT_TRUE(std::regex_match(f.name, video_name)) << f.name;
    EXPECT_EQ(f.camera_id, 3u);
    EXPECT_GT(f.frame_index, last);
    EXPECT_NEAR(f.timestamp, f.frame_index / 30.0, 1e-3);
    char expect[32];
    std::snprintf(expect, sizeof(expect), "flight-%06lld.png", static_cast<long long>(f.frame_index));
    EXPECT_EQ(f.name, expect);
    EXPECT_GT(f.sharpness, 0);
    last = f.frame_index;
  }
  EXPECT_EQ(index.frames[5].frame_index, 0);
  // 4 px/frame on 343 px: a keyframe about every 5 frames by motion, but min gap is 12 at 30 fps.
  EXPECT_GE(index.frames.size() - 5, 90u / 30);
  EXPECT_LE(index.frames.size() - 5, 90u / 12 + 2);
  // Files on disk and the index on disk agree; no staging folder is left.
  const io::FramesIndex back = io::ReadFramesIndex(opt.workspace / "frames" / "frames.json");
  ASSERT_EQ(back.frames.size(), index.frames.size());
  for (const auto& f : back.frames) {
    const cv::Mat img = cv::imread((opt.workspace / "frames" / f.name).string());
    ASSERT_FALSE(img.empty()) << f.name;
    EXPECT_EQ(img.cols, back.FindCamera(f.camera_id)->camera.width) << f.name;
  }
  for (const auto& e : fs::directory_iterator(opt.workspace)) EXPECT_EQ(e.path().filename(), "frames");
}

TEST(FramesIngest, MaxFramesSubsamplesEvenly) {
  MixedInputs in;
  IngestOptions opt;
  opt.workspace = in.tmp / "ws";
  opt.keyframes.all_frames = true;
  opt.max_frames = 4;
  const io::FramesIndex index = IngestFrames({in.video}, opt);
  ASSERT_EQ(index.frames.size(), 4u);
  EXPECT_EQ(index.frames[0].frame_index, 0);
  EXPECT_EQ(index.frames[1].frame_index, 30);
  EXPECT_EQ(index.frames[2].frame_index, 59);
  EXPECT_EQ(index.frames[3].frame_index, 89);
  int files = 0;
  for (const auto& e : fs::directory_iterator(opt.workspace / "frames")) files += e.path().extension() == ".png";
  EXPECT_EQ(files, 4);
}

TEST(FramesIngest, BadInputLeavesWorkspaceUntouched) {
  MixedInputs in;
  const fs::path ws = in.tmp / "ws";
  fs::create_directories(ws / "frames");
  std::ofstream(ws / "frames" / "previous.txt") << "from an earlier run";
  std::ofstream(in.tmp / "broken.png") << "not a png";
  IngestOptions opt;
  opt.workspace = ws;
  try {
    IngestFrames({in.images, in.video, in.tmp / "broken.png"}, opt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("broken.png"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::exists(ws / "frames" / "previous.txt"));
  EXPECT_FALSE(fs::exists(ws / "frames" / "frames.json"));
  for (const auto& e : fs::directory_iterator(ws)) EXPECT_EQ(e.path().filename(), "frames");

  std::ofstream(in.tmp / "notes.xyz") << "neither image nor video";
  try {
    IngestFrames({in.tmp / "notes.xyz"}, opt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("notes.xyz"), std::string::npos) << e.what();
  }
  EXPECT_THROW(IngestFrames({in.tmp / "does-not-exist.mp4"}, opt), Error);
}

TEST(FramesIngest, CorruptVideoKeepsFramesBeforeDamage) {
  MixedInputs in;
  const fs::path full = in.tmp / "full.ts", cut = in.tmp / "cut.ts", stub = in.tmp / "stub.ts";
  test::EncodeVideo(
      full, 60, 30,
      [&](int i) {
        return test::ViewOf(in.tex, {320, 240}, 300 + 3.0 * i, 300);
      },
      "mpeg2video");
  test::TruncateCopy(full, cut, 0.5);
  IngestOptions opt;
  opt.workspace = in.tmp / "ws";
  opt.keyframes.all_frames = true;
  const io::FramesIndex index = IngestFrames({cut}, opt);
  EXPECT_GT(index.frames.size(), 15u);
  EXPECT_LT(index.frames.size(), 45u);
  for (size_t i = 0; i < index.frames.size(); ++i) EXPECT_EQ(index.frames[i].frame_index, static_cast<int64_t>(i));
  // Only the first few hundred bytes: no decodable frame → an error naming the file, frames/ unchanged.
  test::TruncateCopy(full, stub, 0.004);
  try {
    IngestFrames({stub}, opt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("stub.ts"), std::string::npos) << e.what();
  }
  EXPECT_EQ(io::ReadFramesIndex(opt.workspace / "frames" / "frames.json").frames.size(), index.frames.size());
}

TEST(FramesIngest, NonSquarePixelsSetTheAspectPrior) {
  // SD video with 10:11 pixels (narrower than tall): the horizontal focal in pixels is f · 11/10.
  MixedInputs in;
  const fs::path sd = in.tmp / "sd.mkv";
  test::EncodeVideo(
      sd, 10, 30,
      [&](int i) {
        return test::ViewOf(in.tex, {360, 240}, 300 + i, 300);
      },
      "ffv1", 12, 10, 11);
  IngestOptions opt;
  opt.workspace = in.tmp / "ws";
  const io::FramesIndex index = IngestFrames({sd}, opt);
  ASSERT_EQ(index.cameras.size(), 1u);
  EXPECT_NEAR(index.cameras[0].camera.aspect, 1.1, 1e-9);
  EXPECT_DOUBLE_EQ(index.cameras[0].camera.f, 1.2 * 360);
}

TEST(FramesIngest, NameClashesGetUniqueNames) {
  MixedInputs in;
  fs::create_directories(in.tmp / "other");
  fs::copy_file(in.images / "img0.png", in.tmp / "other" / "img0.png");
  IngestOptions opt;
  opt.workspace = in.tmp / "ws";
  const io::FramesIndex index = IngestFrames({in.images / "img0.png", in.tmp / "other" / "img0.png"}, opt);
  ASSERT_EQ(index.frames.size(), 2u);
  EXPECT_EQ(index.frames[0].name, "img0.png");
  EXPECT_EQ(index.frames[1].name, "other-img0.png");
  EXPECT_EQ(index.cameras.size(), 1u);
}

TEST(FramesIngest, RealOneFpsOrbitKeepsMostFrames) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos/aphill_240_1fps_crf32.mp4");
  TempDir tmp("fmv3d-ingest");
  IngestOptions opt;
  opt.workspace = tmp / "ws";
  const io::FramesIndex index = IngestFrames({test::SharedData() / "fmv/kwiver/videos/aphill_240_1fps_crf32.mp4"}, opt);
  // Frames are already 1 s apart: the automatic gaps at 1 fps are 1 frame, so only blurred ones go.
  EXPECT_GE(index.frames.size(), 0.8 * 310);
  EXPECT_LE(index.frames.size(), 310u);
  EXPECT_EQ(index.frames.front().name, "aphill_240_1fps_crf32-000000.png");
  ASSERT_EQ(index.cameras.size(), 1u);
  EXPECT_EQ(index.cameras[0].camera.width, 360);
}

}  // namespace
}  // namespace fmv3d::ingest
