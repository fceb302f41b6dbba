#include "fmv3d/telemetry/dji_srt.h"

#include <gtest/gtest.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::telemetry {
namespace {

TEST(DjiSrt, OlderGpsLayout) {
  const std::string text =
      "1\r\n00:00:00,000 --> 00:00:01,000\r\nHOME(149.0251,-20.2532) 2017.08.05 14:11:51\r\n"
      "GPS(149.0251,-20.2533,16) BAROMETER:1.9\r\nISO:100 Shutter:60 EV:0 Fnum:2.2\r\n\r\n"
      "2\r\n00:00:01,000 --> 00:00:02,000\r\nHOME(149.0251,-20.2532) 2017.08.05 14:11:52\r\n"
      "GPS(149.0253,-20.2535,17M) BAROMETER:3.5M\r\nISO:100 Shutter:60 EV:0 Fnum:2.2\r\n";
  const auto v = ParseDjiSrt(text);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_DOUBLE_EQ(v[0].time, 0.0);
  EXPECT_DOUBLE_EQ(*v[0].sensor_longitude, 149.0251);
  EXPECT_DOUBLE_EQ(*v[0].sensor_latitude, -20.2533);
  EXPECT_DOUBLE_EQ(*v[0].sensor_altitude_msl, 16);
  EXPECT_DOUBLE_EQ(*v[0].sensor_relative_altitude, 1.9);
  EXPECT_DOUBLE_EQ(v[1].time, 1.0);
  EXPECT_DOUBLE_EQ(*v[1].sensor_latitude, -20.2535);
  EXPECT_DOUBLE_EQ(*v[1].sensor_altitude_msl, 17);
  EXPECT_DOUBLE_EQ(*v[1].sensor_relative_altitude, 3.5);
  EXPECT_EQ(v[1].source, "DJI-SRT");
}

TEST(DjiSrt, NewerBracketLayout) {
  const std::string text =
      "1\n00:00:00,000 --> 00:00:00,033\n<font size=\"28\">FrameCnt: 1, DiffTime: 33ms\n"
      "2023-05-12 10:22:33.123\n[iso: 100] [shutter: 1/500.0] [fnum: 2.8] [ev: 0] [ct: 5500] "
      "[color_md: default] [focal_len: 24.00] [latitude: 47.123456] [longitude: 8.654321] "
      "[rel_alt: 50.300 abs_alt: 512.345] </font>\n\n"
      "2\n00:00:00,033 --> 00:00:00,066\n<font size=\"28\">FrameCnt: 2, DiffTime: 33ms\n"
      "2023-05-12 10:22:33.156\n[iso: 100] [latitude : 47.123466] [longtitude : 8.654331] "
      "[altitude: 513.0] [gb_yaw: -12.5 gb_pitch: -90.0 gb_roll: 0.1]</font>\n\n"
      "3\n00:00:00,066 --> 00:00:00,100\n[latitude: 0.000000] [longitude: 0.000000] [rel_alt: 0 abs_alt: 0]\n";
  const auto v = ParseDjiSrt(text);
  ASSERT_EQ(v.size(), 2u);  // the third has no GPS fix (0, 0)
  EXPECT_DOUBLE_EQ(v[0].time, 0.0);
  EXPECT_DOUBLE_EQ(*v[0].sensor_latitude, 47.123456);
  EXPECT_DOUBLE_EQ(*v[0].sensor_longitude, 8.654321);
  EXPECT_DOUBLE_EQ(*v[0].sensor_relative_altitude, 50.3);
  EXPECT_DOUBLE_EQ(*v[0].sensor_altitude_msl, 512.345);
  EXPECT_FALSE(v[0].gimbal_yaw.has_value());
  EXPECT_DOUBLE_EQ(v[1].time, 0.033);
  EXPECT_DOUBLE_EQ(*v[1].sensor_longitude, 8.654331);
  EXPECT_DOUBLE_EQ(*v[1].sensor_altitude_msl, 513.0);
  EXPECT_DOUBLE_EQ(*v[1].gimbal_yaw, -12.5);
  EXPECT_DOUBLE_EQ(*v[1].gimbal_pitch, -90.0);
  // Interpolated between the two subtitles.
  const auto mid = InterpolateTelemetry(v, 0.0165);
  ASSERT_TRUE(mid);
  EXPECT_NEAR(*mid->sensor_latitude, 47.123461, 1e-9);
}

TEST(DjiSrt, GarbageAndEmptyInputGiveNoSamples) {
  EXPECT_TRUE(ParseDjiSrt("").empty());
  EXPECT_TRUE(ParseDjiSrt("1\nnot a time\nGPS(1,2,3)\n").empty());
  EXPECT_TRUE(ParseDjiSrt("1\n00:00:01,000 --> 00:00:02,000\nno telemetry here\n").empty());
  EXPECT_TRUE(ParseDjiSrt("1\n00:00:01,000 --> 00:00:02,000\n[latitude: 95.0] [longitude: 8.0]\n").empty());
}

TEST(DjiSrt, FileBesideAVideo) {
  test::TempDir dir;
  EXPECT_FALSE(FindDjiSrtBeside(dir / "DJI_0001.MP4").has_value());
  core::WriteTextFile(dir / "DJI_0001.SRT", "1\n00:01:02,500 --> 00:01:03,000\nGPS(8.5,47.25,400)\n");
  const auto p = FindDjiSrtBeside(dir / "DJI_0001.MP4");
  ASSERT_TRUE(p.has_value());
  const auto v = ReadDjiSrt(*p);
  ASSERT_EQ(v.size(), 1u);
  EXPECT_DOUBLE_EQ(v[0].time, 62.5);
  EXPECT_THROW(ReadDjiSrt(dir / "missing.SRT"), Error);
}

}  // namespace
}  // namespace fmv3d::telemetry
