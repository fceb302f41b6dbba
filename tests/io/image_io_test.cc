#include "fmv3d/io/image_io.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/io/exif.h"
#include "image_test_util.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

using test::TempDir;

// Random colours at 1/8 resolution, upsampled: smooth enough for JPEG to keep it within a few grey levels.
cv::Mat SmoothTexture(cv::Size size, uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat small(size.height / 8 + 2, size.width / 8 + 2, CV_8UC3), out;
  rng.fill(small, cv::RNG::UNIFORM, 0, 256);
  cv::resize(small, out, size, 0, 0, cv::INTER_CUBIC);
  return out;
}

TEST(ImageIo, ReadsEveryAcceptedFormat) {
  TempDir tmp("fmv3d-img");
  const cv::Mat img = SmoothTexture({255, 171}, 21);
  struct Case {
    std::string name;
    double tolerance;  // mean absolute difference
  };
  for (const Case& c : {Case{"a.png", 0}, Case{"a.bmp", 0}, Case{"a.tif", 0}, Case{"a.jpg", 10}, Case{"b.JPEG", 10}}) {
    ASSERT_TRUE(cv::imwrite((tmp / c.name).string(), img)) << c.name;
    const cv::Mat back = ReadImage(tmp / c.name);
    ASSERT_EQ(back.size(), img.size()) << c.name;
    ASSERT_EQ(back.type(), CV_8UC3) << c.name;
    cv::Mat d;
    cv::absdiff(back, img, d);
    EXPECT_LE(cv::mean(d)[0], c.tolerance) << c.name;
    EXPECT_TRUE(HasImageExtension(tmp / c.name));
  }
  // Atomic write: the file appears complete under its name, no temporary left.
  WriteImage(tmp / "out.png", img);
  EXPECT_EQ(cv::norm(ReadImage(tmp / "out.png"), img, cv::NORM_INF), 0);
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(tmp.path())) files += e.path().filename().string()[0] == '.';
  EXPECT_EQ(files, 0);
}

TEST(ImageIo, BadFilesThrowNamingTheFile) {
  TempDir tmp("fmv3d-img");
  {
    std::ofstream(tmp / "text.png") << "this is not a PNG";
    std::ofstream(tmp / "empty.jpg");
    std::ofstream(tmp / "junk.gif") << "GIF89a but nothing else";
  }
  for (const char* name : {"text.png", "empty.jpg", "junk.gif", "missing.tif"}) {
    try {
      ReadImage(tmp / name);
      ADD_FAILURE() << "no error for " << name;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

TEST(ImageIo, ExifFromJpeg) {
  TempDir tmp("fmv3d-img");
  const cv::Mat img = SmoothTexture({96, 64}, 22);
  cv::imwrite((tmp / "dji.jpg").string(), img);
  test::AddExifToJpeg(tmp / "dji.jpg", test::MakeExif("DJI", "FC6310", 88, 10, 24));
  const ExifInfo e = ReadExif(tmp / "dji.jpg");
  EXPECT_EQ(e.make, "DJI");
  EXPECT_EQ(e.model, "FC6310");
  EXPECT_DOUBLE_EQ(e.focal_mm, 8.8);
  EXPECT_DOUBLE_EQ(e.focal_35mm, 24);
  EXPECT_EQ(ReadImage(tmp / "dji.jpg").size(), img.size());  // still a valid JPEG
  // No EXIF at all.
  cv::imwrite((tmp / "plain.jpg").string(), img);
  EXPECT_TRUE(ReadExif(tmp / "plain.jpg").empty());
  EXPECT_TRUE(ReadExif(tmp / "missing.jpg").empty());
}

TEST(ImageIo, MalformedExifNeverReadsOutOfBounds) {
  // Every truncation and a sweep of single-byte corruptions of a valid block: the parser must stay in
  // bounds (ASan checks) and never invent a focal length out of range.
  const auto good = test::MakeExif("Canon", "Canon EOS 5D Mark III", 50, 1, 50);
  for (size_t n = 0; n <= good.size(); ++n) {
    const ExifInfo e = ParseTiffExif(good.data(), n);
    EXPECT_TRUE(e.focal_mm == 0 || e.focal_mm == 50);
  }
  for (size_t i = 0; i < good.size(); ++i) {
    for (unsigned char v : {0x00, 0x7F, 0xFF}) {
      auto bad = good;
      bad[i] = v;
      const ExifInfo e = ParseTiffExif(bad.data(), bad.size());
      EXPECT_TRUE(e.focal_mm >= 0 && e.focal_mm < 5000);
    }
  }
  EXPECT_EQ(ParseTiffExif(good.data(), good.size()).model, "Canon EOS 5D Mark III");
}

}  // namespace
}  // namespace fmv3d::io
