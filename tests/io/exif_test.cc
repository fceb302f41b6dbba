// EXIF GPS / XMP: the parser against the writer (exact values), against malformed bytes, and on real camera
// JPEGs (../shared/data/photos/exif-gps, values from its README).
#include "fmv3d/io/exif.h"

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/io/exif_writer.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

ExifInfo Sample() {
  ExifInfo e;
  e.make = "DJI";
  e.model = "FC3411";
  e.focal_mm = 8.38;
  e.focal_35mm = 24;
  e.datetime_original = "2024:06:01 12:00:05";
  e.gps.latitude = -33.8567844;
  e.gps.longitude = 151.2152967;
  e.gps.altitude = -12.345;  // below sea level: GPSAltitudeRef 1
  e.gps.dop = 1.7;
  e.gps.horizontal_error = 2.5;
  e.gps.status = 'A';
  e.gps.measure_mode = '3';
  e.gps.map_datum = "WGS-84";
  e.gps.utc_seconds = 1717243205.25;
  return e;
}

TEST(Exif, GpsRoundTrip) {
  const ExifInfo in = Sample();
  const auto tiff = EncodeTiffExif(in);
  const ExifInfo out = ParseTiffExif(tiff.data(), tiff.size());
  EXPECT_EQ(out.make, "DJI");
  EXPECT_EQ(out.model, "FC3411");
  EXPECT_NEAR(out.focal_mm, 8.38, 1e-9);
  EXPECT_EQ(out.focal_35mm, 24);
  EXPECT_EQ(out.datetime_original, in.datetime_original);
  // 1e-4 s of arc = 3e-8 degrees.
  EXPECT_NEAR(*out.gps.latitude, *in.gps.latitude, 3e-8);
  EXPECT_NEAR(*out.gps.longitude, *in.gps.longitude, 3e-8);
  EXPECT_NEAR(*out.gps.altitude, -12.345, 1e-9);
  EXPECT_NEAR(*out.gps.dop, 1.7, 1e-9);
  EXPECT_NEAR(*out.gps.horizontal_error, 2.5, 1e-9);
  EXPECT_EQ(out.gps.status, 'A');
  EXPECT_EQ(out.gps.measure_mode, '3');
  EXPECT_EQ(out.gps.map_datum, "WGS-84");
  EXPECT_NEAR(*out.gps.utc_seconds, 1717243205.25, 1e-6);
}

TEST(Exif, JpegWithExifAndXmpSegments) {
  test::TempDir tmp("fmv3d-exif");
  std::vector<uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(64, 96, CV_8UC3, cv::Scalar(40, 90, 160)), jpeg));
  const std::string xmp = "<x:xmpmeta drone-dji:GimbalPitchDegree=\"-90.0\"/>";
  const auto bytes = InsertJpegMetadata(jpeg, EncodeTiffExif(Sample()), xmp);
  {
    std::ofstream f(tmp / "a.jpg", std::ios::binary);
    f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  const ExifInfo e = ReadExif(tmp / "a.jpg");
  EXPECT_EQ(e.model, "FC3411");
  EXPECT_NEAR(*e.gps.latitude, -33.8567844, 3e-8);
  EXPECT_EQ(e.xmp, xmp);
  EXPECT_EQ(cv::imread((tmp / "a.jpg").string()).cols, 96);  // still a valid JPEG
  EXPECT_THROW(InsertJpegMetadata({1, 2, 3, 4}, {}, ""), Error);
  EXPECT_THROW(InsertJpegMetadata(jpeg, {}, std::string(70000, 'x')), Error);
}

TEST(Exif, MalformedGpsNeverReadsOutOfBounds) {
  const auto good = EncodeTiffExif(Sample());
  for (size_t n = 0; n <= good.size(); ++n) {
    const ExifInfo e = ParseTiffExif(good.data(), n);
    if (e.gps.latitude) EXPECT_LE(std::abs(*e.gps.latitude), 90 * 3.0);
  }
  for (size_t i = 0; i < good.size(); ++i)
    for (unsigned char v : {0x00, 0x7F, 0xFF}) {
      auto bad = good;
      bad[i] = v;
      const ExifInfo e = ParseTiffExif(bad.data(), bad.size());
      if (e.gps.latitude) EXPECT_TRUE(std::isfinite(*e.gps.latitude));
    }
  // A JPEG whose segment length runs past the end.
  const std::vector<unsigned char> jpeg = {0xFF, 0xD8, 0xFF, 0xE1, 0xFF, 0xF0, 'E', 'x', 'i', 'f', 0, 0};
  EXPECT_FALSE(ParseImageMetadata(jpeg.data(), jpeg.size()).gps.present());
}

TEST(Exif, FocalPlaneResolutionRoundTrip) {
  ExifInfo in = Sample();
  in.focal_plane_x_res = 5472 / 13.2;  // pixels per mm
  in.pixel_width = 5472;
  const auto tiff = EncodeTiffExif(in);
  const ExifInfo out = ParseTiffExif(tiff.data(), tiff.size());
  EXPECT_FALSE(out.damaged);
  EXPECT_NEAR(out.focal_plane_x_res, in.focal_plane_x_res, 1e-3 / 25.4);  // written per inch to 1e-3
  EXPECT_EQ(out.pixel_width, 5472);
}

// A block that is there but unreadable is told apart from no block (frames counts and warns about it).
TEST(Exif, DamagedBlockIsFlagged) {
  const std::vector<unsigned char> bad_ifd = {'I', 'I', 42, 0, 0xFF, 0xFF, 0xFF, 0x7F};
  EXPECT_TRUE(ParseTiffExif(bad_ifd.data(), bad_ifd.size()).damaged);
  const std::vector<unsigned char> bad_magic = {'I', 'I', 43, 0, 8, 0, 0, 0, 0, 0};
  EXPECT_TRUE(ParseTiffExif(bad_magic.data(), bad_magic.size()).damaged);
  const auto good = EncodeTiffExif(Sample());
  EXPECT_FALSE(ParseTiffExif(good.data(), good.size()).damaged);
  std::vector<uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(16, 16, CV_8UC3, cv::Scalar(1, 2, 3)), jpeg));
  const auto no_exif = ParseImageMetadata(jpeg.data(), jpeg.size());
  EXPECT_FALSE(no_exif.damaged);
  const auto damaged = InsertJpegMetadata(jpeg, std::vector<uint8_t>(bad_ifd.begin(), bad_ifd.end()), "");
  EXPECT_TRUE(ParseImageMetadata(damaged.data(), damaged.size()).damaged);
}

TEST(Exif, OutOfRangeIntegersAreDroppedNotCast) {
  // Found by exif_fuzz: a PixelXDimension rational of 2684354560/1 was cast to int (undefined behaviour).
  std::vector<unsigned char> b = {'I', 'I', 42, 0, 8, 0, 0, 0};
  auto u16 = [&](uint16_t v) { b.push_back(v & 0xFF), b.push_back(v >> 8); };
  auto u32 = [&](uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back((v >> (8 * i)) & 0xFF);
  };
  u16(1), u16(0x8769), u16(4), u32(1), u32(26), u32(0);  // IFD0 at 8: the EXIF IFD pointer
  u16(1), u16(0xA002), u16(5), u32(1), u32(44), u32(0);  // EXIF IFD at 26: PixelXDimension
  u32(2684354560u), u32(1);                              // the rational at 44
  ASSERT_EQ(b.size(), 52u);
  EXPECT_EQ(ParseTiffExif(b.data(), b.size()).pixel_width, 0);
  b[44] = 0x40, b[45] = 0x1F, b[46] = 0, b[47] = 0;  // 8000
  EXPECT_EQ(ParseTiffExif(b.data(), b.size()).pixel_width, 8000);
}

TEST(Exif, RealCameraJpegs) {
  FMV3D_REQUIRE_SHARED_DATA("photos/exif-gps/DSCN0010.jpg");
  struct Case {
    const char* file;
    double lat, lon;
  };
  const Case cases[] = {{"DSCN0010.jpg", 43.467448, 11.885127}, {"DSCN0012.jpg", 43.467157, 11.885395},
                        {"DSCN0021.jpg", 43.467082, 11.884538}, {"DSCN0025.jpg", 43.468365, 11.881635},
                        {"DSCN0027.jpg", 43.468442, 11.881515}, {"DSCN0029.jpg", 43.468243, 11.880172},
                        {"DSCN0038.jpg", 43.467255, 11.879213}, {"DSCN0040.jpg", 43.466012, 11.879112},
                        {"DSCN0042.jpg", 43.464455, 11.881478}};
  for (const Case& c : cases) {
    const ExifInfo e = ReadExif(test::SharedData() / "photos/exif-gps" / c.file);
    EXPECT_EQ(e.make, "NIKON") << c.file;
    ASSERT_TRUE(e.gps.latitude && e.gps.longitude) << c.file;
    EXPECT_NEAR(*e.gps.latitude, c.lat, 1e-6) << c.file;
    EXPECT_NEAR(*e.gps.longitude, c.lon, 1e-6) << c.file;
    EXPECT_FALSE(e.gps.altitude.has_value()) << c.file;
  }
}

}  // namespace
}  // namespace fmv3d::io
