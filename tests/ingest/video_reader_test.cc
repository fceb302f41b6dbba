#include "fmv3d/ingest/video_reader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "test_util.h"
#include "video_test_util.h"

namespace fmv3d::ingest {
namespace {

using test::TempDir;

// Decodes a generated video and checks count, order, timestamps and pixels against what was encoded.
void CheckRoundTrip(const std::string& file, const std::string& codec, cv::Size size, int n, double fps,
                    double max_mean_abs_diff) {
  TempDir tmp("fmv3d-video");
  const cv::Mat tex = test::RandomTexture(size.width * 2, size.height * 2, 3);
  auto frame = [&](int i) { return test::ViewOf(tex, size, size.width * 0.7 + 2.0 * i, size.height, 1.0); };
  const auto path = tmp / file;
  test::EncodeVideo(path, n, fps, frame, codec);

  VideoReader reader(path);
  EXPECT_EQ(reader.info().width, size.width);
  EXPECT_EQ(reader.info().height, size.height);
  EXPECT_NEAR(reader.info().fps, fps, 0.01);
  VideoFrame f;
  int count = 0;
  double worst = 0;
  while (reader.Read(&f)) {
    ASSERT_EQ(f.index, count);
    EXPECT_NEAR(f.timestamp, count / fps, 0.5 / fps) << "frame " << count;
    ASSERT_EQ(f.image.size(), size);
    cv::Mat diff;
    cv::absdiff(f.image, frame(count), diff);
    worst = std::max(worst, cv::mean(diff)[0]);
    ++count;
  }
  EXPECT_EQ(count, n);
  EXPECT_TRUE(reader.warning().empty()) << reader.warning();
  EXPECT_LT(worst, max_mean_abs_diff) << codec;
}

TEST(VideoReader, Mpeg4InMp4) { CheckRoundTrip("a.mp4", "mpeg4", {320, 240}, 40, 30, 12); }
TEST(VideoReader, OddSizeLossless) { CheckRoundTrip("odd.mkv", "ffv1", {255, 171}, 25, 25, 3); }
TEST(VideoReader, Mpeg2InTransportStream) { CheckRoundTrip("a.ts", "mpeg2video", {254, 270}, 30, 30000.0 / 1001, 12); }
TEST(VideoReader, MjpegInAvi) { CheckRoundTrip("a.avi", "mjpeg", {343, 259}, 20, 10, 12); }

TEST(VideoReader, TruncatedKeepsFramesBeforeDamage) {
  TempDir tmp("fmv3d-video");
  const cv::Mat tex = test::RandomTexture(640, 480, 5);
  const int n = 60;
  // Every frame is an I-frame so damage cannot reach back; truncation at 60% of the bytes.
  for (const std::string ext : {".ts", ".avi", ".mkv"}) {
    const auto full = tmp / ("full" + ext), cut = tmp / ("cut" + ext);
    test::EncodeVideo(
        full, n, 30,
        [&](int i) {
          return test::ViewOf(tex, {320, 240}, 200 + 3 * i, 240);
        },
        "mpeg4", 1);
    test::TruncateCopy(full, cut, 0.6);
    VideoReader reader(cut);
    VideoFrame f;
    int count = 0;
    while (reader.Read(&f)) {
      EXPECT_EQ(f.index, count);
      ++count;
    }
    EXPECT_GT(count, n / 3) << ext;
    EXPECT_LT(count, n) << ext;
    EXPECT_FALSE(reader.warning().empty()) << ext;
    // Every returned frame is intact: the last one matches what was encoded.
    cv::Mat diff;
    cv::absdiff(f.image, test::ViewOf(tex, {320, 240}, 200 + 3 * (count - 1), 240), diff);
    EXPECT_LT(cv::mean(diff)[0], 12) << ext;
  }
}

TEST(VideoReader, TruncatedMp4WithoutIndexThrowsNamingIt) {
  // Our muxer writes the mp4 index (moov) at the end: cut in half, nothing is decodable and the error must
  // name the file.
  TempDir tmp("fmv3d-video");
  const cv::Mat tex = test::RandomTexture(640, 480, 6);
  const auto full = tmp / "full.mp4", cut = tmp / "cut.mp4";
  test::EncodeVideo(
      full, 40, 30,
      [&](int i) {
        return test::ViewOf(tex, {320, 240}, 200 + 3 * i, 240);
      },
      "mpeg4");
  test::TruncateCopy(full, cut, 0.5);
  try {
    VideoReader reader(cut);
    FAIL() << "opened an mp4 without its index";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cut.mp4"), std::string::npos) << e.what();
  }
}

TEST(VideoReader, GarbageFileThrowsNamingIt) {
  TempDir tmp("fmv3d-video");
  const auto path = tmp / "noise.mp4";
  {
    std::ofstream out(path, std::ios::binary);
    for (int i = 0; i < 5000; ++i) out.put(static_cast<char>((i * 7919) % 251));
  }
  try {
    VideoReader reader(path);
    FAIL() << "no error for a garbage file";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("noise.mp4"), std::string::npos) << e.what();
  }
  EXPECT_THROW(VideoReader(tmp / "missing.mp4"), Error);
  EXPECT_FALSE(IsVideo(path));
}

TEST(VideoReader, RealKwiverClips) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos");
  const auto dir = test::SharedData() / "fmv/kwiver/videos";
  struct Clip {
    const char* name;
    int width, height, min_frames;
  };
  for (const Clip& c :
       {Clip{"aphill_240_1fps_crf32.mp4", 360, 240, 310}, Clip{"aphill_klv_10s.ts", 360, 240, 10},
        Clip{"aphill_short.ts", 720, 480, 40}, Clip{"h264_klv.ts", 160, 120, 30}, Clip{"h265_klv.ts", 160, 120, 30},
        Clip{"mpeg2_klv.ts", 160, 120, 30}, Clip{"h264_no_klv.ts", 160, 120, 30}}) {
    VideoReader reader(dir / c.name);
    EXPECT_EQ(reader.info().width, c.width) << c.name;
    EXPECT_EQ(reader.info().height, c.height) << c.name;
    VideoFrame f;
    int count = 0;
    double last_t = -1;
    while (reader.Read(&f)) {
      EXPECT_GT(f.timestamp, last_t) << c.name << " frame " << count;
      last_t = f.timestamp;
      ++count;
    }
    EXPECT_GE(count, c.min_frames) << c.name;
    if (std::string(c.name) == "aphill_240_1fps_crf32.mp4") {
      EXPECT_EQ(count, 310);
      EXPECT_NEAR(last_t, 309.0, 1e-6);
    }
    EXPECT_TRUE(reader.warning().empty()) << c.name << ": " << reader.warning();
  }
}

TEST(ReadInputImage, GifThroughFfmpegOthersThroughOpenCv) {
  TempDir tmp("fmv3d-img");
  const cv::Mat img = test::ViewOf(test::RandomTexture(400, 300, 21), {255, 171}, 200, 150);
  // GIF (palette): through FFmpeg, since OpenCV 4.6 has none.
  test::EncodeVideo(
      tmp / "a.gif", 1, 10, [&](int) { return img; }, "gif");
  const cv::Mat gif = ReadInputImage(tmp / "a.gif");
  ASSERT_EQ(gif.size(), img.size());
  cv::Mat d;
  cv::absdiff(gif, img, d);
  EXPECT_LT(cv::mean(d)[0], 40);  // 256-colour palette
  cv::imwrite((tmp / "a.png").string(), img);
  EXPECT_EQ(cv::norm(ReadInputImage(tmp / "a.png"), img, cv::NORM_INF), 0);
  std::ofstream(tmp / "junk.gif") << "GIF89a but nothing else";
  for (const char* name : {"junk.gif", "missing.gif"}) {
    try {
      ReadInputImage(tmp / name);
      ADD_FAILURE() << "no error for " << name;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace fmv3d::ingest
