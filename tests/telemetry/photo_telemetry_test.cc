// Photo telemetry: DJI XMP in both serialisations, the altitude datum, the attitude chain, and the fixes that
// must never reach a georeference ((0, 0), no lock, huge DOP, out of range, corrupt values).
#include "fmv3d/telemetry/photo_telemetry.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <functional>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/attitude.h"

namespace fmv3d::telemetry {
namespace {

io::ExifInfo Photo() {
  io::ExifInfo e;
  e.make = "DJI";
  e.gps.latitude = 47.3977;
  e.gps.longitude = 8.5456;
  e.gps.altitude = 512.25;
  e.gps.dop = 1.2;
  e.gps.measure_mode = '3';
  e.gps.utc_seconds = 1717243200.5;
  return e;
}

TEST(DjiXmp, AttributesElementsAndDjisSpelling) {
  const std::string attrs =
      "<rdf:Description xmlns:drone-dji=\"http://www.dji.com/drone-dji/1.0/\" drone-dji:AbsoluteAltitude=\"+512.37\" "
      "drone-dji:RelativeAltitude=\"+80.10\" drone-dji:GimbalRollDegree=\"+0.00\" drone-dji:GimbalYawDegree=\"-45.50\" "
      "drone-dji:GimbalPitchDegree=\"-89.90\" drone-dji:FlightRollDegree=\"+1.20\" "
      "drone-dji:FlightYawDegree=\"-44.90\" "
      "drone-dji:FlightPitchDegree=\"-3.10\" drone-dji:GpsLongtitude=\"8.5456\" drone-dji:RtkFlag='50' "
      "drone-dji:RtkStdLon=\"0.012\" drone-dji:RtkStdLat=\"0.015\" drone-dji:RtkStdHgt=\"0.030\"/>";
  const DjiXmp d = ParseDjiXmp(attrs);
  EXPECT_DOUBLE_EQ(*d.absolute_altitude, 512.37);
  EXPECT_DOUBLE_EQ(*d.relative_altitude, 80.10);
  EXPECT_DOUBLE_EQ(*d.gimbal_yaw, -45.5);
  EXPECT_DOUBLE_EQ(*d.gimbal_pitch, -89.9);
  EXPECT_DOUBLE_EQ(*d.flight_pitch, -3.1);
  EXPECT_DOUBLE_EQ(*d.longitude, 8.5456);
  EXPECT_DOUBLE_EQ(*d.rtk_flag, 50);
  EXPECT_DOUBLE_EQ(*d.rtk_std_hgt, 0.03);
  EXPECT_EQ(d.malformed, 0u);
  const DjiXmp e = ParseDjiXmp(
      "<drone-dji:GimbalPitchDegree> -30.5 </drone-dji:GimbalPitchDegree><drone-dji:AbsoluteAltitude>abc"
      "</drone-dji:AbsoluteAltitude><drone-dji:GimbalYawDegree>nan</drone-dji:GimbalYawDegree>");
  EXPECT_DOUBLE_EQ(*e.gimbal_pitch, -30.5);
  EXPECT_FALSE(e.absolute_altitude.has_value());
  EXPECT_FALSE(e.gimbal_yaw.has_value());
  EXPECT_EQ(e.malformed, 2u);
  // Truncated and empty packets.
  for (const std::string& s : {std::string("drone-dji:"), std::string("drone-dji:GimbalYawDegree=\"12"),
                               std::string("drone-dji:X"), std::string()})
    EXPECT_FALSE(ParseDjiXmp(s).gimbal_yaw.has_value());
}

TEST(DjiXmp, EncodeParseRoundTrip) {
  DjiXmp d;
  d.gimbal_yaw = 123.456789;
  d.gimbal_pitch = -60;
  d.relative_altitude = 99.5;
  const DjiXmp back = ParseDjiXmp(EncodeDjiXmp(d));
  EXPECT_NEAR(*back.gimbal_yaw, 123.456789, 1e-8);
  EXPECT_DOUBLE_EQ(*back.gimbal_pitch, -60);
  EXPECT_DOUBLE_EQ(*back.relative_altitude, 99.5);
  EXPECT_FALSE(back.flight_yaw.has_value());
  EXPECT_EQ(back.fields, 3u);
}

TEST(PhotoTelemetry, ExifPositionAltitudeDatumAndQuality) {
  io::ExifInfo e = Photo();
  PhotoTelemetry t = TelemetryFromPhoto(e, {});
  ASSERT_TRUE(t.sample);
  EXPECT_EQ(t.rejection, FixRejection::kNone);
  EXPECT_EQ(t.sample->source, "EXIF");
  EXPECT_DOUBLE_EQ(*t.sample->sensor_latitude, 47.3977);
  EXPECT_DOUBLE_EQ(*t.sample->sensor_altitude_msl, 512.25);  // EXIF: above sea level
  EXPECT_FALSE(t.sample->sensor_altitude_hae.has_value());
  EXPECT_DOUBLE_EQ(*t.sample->gps_dop, 1.2);
  EXPECT_EQ(*t.sample->gps_fix, 3);
  EXPECT_EQ(*t.sample->unix_time_us, 1717243200500000u);
  PhotoTelemetryOptions o;
  o.altitude_datum = AltitudeDatum::kEllipsoid;
  t = TelemetryFromPhoto(e, o);
  EXPECT_DOUBLE_EQ(*t.sample->sensor_altitude_hae, 512.25);
  EXPECT_FALSE(t.sample->sensor_altitude_msl.has_value());
  // DJI's AbsoluteAltitude wins over EXIF's (more digits); RelativeAltitude is kept beside it.
  e.xmp = "drone-dji:AbsoluteAltitude=\"+512.37\" drone-dji:RelativeAltitude=\"+80.1\"";
  t = TelemetryFromPhoto(e, {});
  EXPECT_EQ(t.sample->source, "EXIF+DJI-XMP");
  EXPECT_DOUBLE_EQ(*t.sample->sensor_altitude_msl, 512.37);
  EXPECT_DOUBLE_EQ(*t.sample->sensor_relative_altitude, 80.1);
  EXPECT_THROW(ParseAltitudeDatum("geoid"), Error);
}

TEST(PhotoTelemetry, GimbalAndFlightAnglesGiveTheSt0601Chain) {
  io::ExifInfo e = Photo();
  e.xmp =
      "drone-dji:GimbalYawDegree=\"-45.5\" drone-dji:GimbalPitchDegree=\"-60\" drone-dji:GimbalRollDegree=\"0.5\" "
      "drone-dji:FlightYawDegree=\"-40\" drone-dji:FlightPitchDegree=\"-5\" drone-dji:FlightRollDegree=\"2\"";
  const PhotoTelemetry t = TelemetryFromPhoto(e, {});
  ASSERT_TRUE(t.sample && t.sample->sensor_relative_azimuth);
  const TelemetrySample& s = *t.sample;
  EXPECT_DOUBLE_EQ(*s.platform_heading, 320);
  St0601Attitude a{*s.platform_heading,          *s.platform_pitch,      *s.platform_roll, *s.sensor_relative_azimuth,
                   *s.sensor_relative_elevation, *s.sensor_relative_roll};
  EXPECT_LT((CameraToEnuFromSt0601(a) - CameraToEnuFromGimbal(-45.5, -60, 0.5)).norm(), 1e-9);
  // Nadir gimbal: the camera looks down (−Up) and its image top (−y) points along the gimbal yaw (north here).
  const Eigen::Matrix3d nadir = CameraToEnuFromGimbal(0, -90, 0);
  EXPECT_LT((nadir.col(2) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-12);
  EXPECT_LT((-nadir.col(1) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
  const Eigen::Vector3d g = GimbalFromCameraToEnu(CameraToEnuFromGimbal(-45.5, -60, 0.5));
  EXPECT_NEAR(g[0], -45.5, 1e-9);
  EXPECT_NEAR(g[1], -60, 1e-9);
  EXPECT_NEAR(g[2], 0.5, 1e-9);
}

TEST(PhotoTelemetry, BadFixesAreRejectedNeverUsed) {
  struct Case {
    const char* what;
    std::function<void(io::ExifInfo*)> spoil;
    FixRejection expected;
  };
  const Case cases[] = {
      {"no GPS", [](io::ExifInfo* e) { e->gps = {}; }, FixRejection::kNoPosition},
      {"(0, 0)", [](io::ExifInfo* e) { e->gps.latitude = 0.0, e->gps.longitude = 0.0; }, FixRejection::kZeroFix},
      {"void", [](io::ExifInfo* e) { e->gps.status = 'V'; }, FixRejection::kNoLock},
      {"DOP 50", [](io::ExifInfo* e) { e->gps.dop = 50.0; }, FixRejection::kPoorDop},
      {"error 500 m", [](io::ExifInfo* e) { e->gps.horizontal_error = 500.0; }, FixRejection::kPoorAccuracy},
      {"lat 95", [](io::ExifInfo* e) { e->gps.latitude = 95.0; }, FixRejection::kOutOfRange},
      {"alt 90 km", [](io::ExifInfo* e) { e->gps.altitude = 90000.0; }, FixRejection::kOutOfRange},
      {"XMP alt 1e9", [](io::ExifInfo* e) { e->xmp = "drone-dji:AbsoluteAltitude=\"1e9\""; },
       FixRejection::kOutOfRange},
  };
  FixCounts counts;
  for (const Case& c : cases) {
    io::ExifInfo e = Photo();
    c.spoil(&e);
    const PhotoTelemetry t = TelemetryFromPhoto(e, {});
    EXPECT_FALSE(t.sample.has_value()) << c.what;
    EXPECT_EQ(t.rejection, c.expected) << c.what;
    counts.Add(t.rejection);
  }
  EXPECT_EQ(counts.Rejected(), 7u);  // "no GPS" is not a bad fix
  EXPECT_EQ(
      counts.Summary("photo fixes"),
      "7 of 7 photo fixes dropped: 1 (0, 0) fix, 3 out of range, 1 no lock, 1 DOP too large, 1 accuracy too poor");
  // DJI writes RTK standard deviations of 0 without an RTK solution: not an accuracy claim.
  io::ExifInfo e = Photo();
  e.xmp = "drone-dji:RtkFlag=\"0\" drone-dji:RtkStdLon=\"0\" drone-dji:RtkStdLat=\"0\"";
  EXPECT_FALSE(TelemetryFromPhoto(e, {}).sample->horizontal_accuracy.has_value());
  e.xmp = "drone-dji:RtkFlag=\"50\" drone-dji:RtkStdLon=\"0.02\" drone-dji:RtkStdLat=\"0.03\"";
  EXPECT_DOUBLE_EQ(*TelemetryFromPhoto(e, {}).sample->horizontal_accuracy, 0.03);
}

}  // namespace
}  // namespace fmv3d::telemetry
