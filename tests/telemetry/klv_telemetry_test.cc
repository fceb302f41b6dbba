// TelemetrySample: extraction from decoded packets, interpolation (angle wrap, nearest for discrete fields,
// extrapolation limits), JSON.
#include <gtest/gtest.h>

#include <algorithm>

#include "fmv3d/telemetry/klv_st0601.h"
#include "fmv3d/telemetry/telemetry.h"
#include "klv_test_bytes.h"

namespace fmv3d::telemetry {
namespace {

using klv::test::BigEndian;
using klv::test::Tlv;

TelemetrySample Sample(double t, double lat, double lon, double heading) {
  TelemetrySample s;
  s.time = t;
  s.source = "ST0601";
  s.sensor_latitude = lat;
  s.sensor_longitude = lon;
  s.platform_heading = heading;
  return s;
}

TEST(Telemetry, SampleFromSt0601Packet) {
  const auto bytes = klv::test::St0601Packet(
      {Tlv(2, BigEndian(1224807209913000ull, 8)), Tlv(13, BigEndian(0x5595B66D, 4)), Tlv(14, BigEndian(0x5B5360C4, 4)),
       Tlv(15, BigEndian(0xC221, 2)), Tlv(5, BigEndian(0x71C2, 2)), Tlv(6, BigEndian(0xFD3D, 2)),
       Tlv(90, BigEndian(0xFF62E2F2, 4)), Tlv(16, BigEndian(0xCD9C, 2)),
       Tlv(19, {0x80, 0x00, 0x00, 0x00}),  // error value -> no elevation
       Tlv(104, {0x2F, 0x92, 0x1E})});
  std::vector<klv::Packet> packets;
  klv::ParseStats stats;
  klv::ParseBuffer(klv::ByteSpan(bytes.data(), bytes.size()), &packets, &stats);
  ASSERT_EQ(packets.size(), 1u);
  packets[0].time_seconds = 1.5;
  const auto s = SampleFromPacket(packets[0]);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->time, 1.5);
  EXPECT_NEAR(*s->sensor_latitude, 60.176822966978335, 1e-12);
  EXPECT_NEAR(*s->sensor_longitude, 128.42675904204452, 1e-12);
  EXPECT_NEAR(*s->sensor_altitude_msl, 14190.72, 0.16);
  EXPECT_NEAR(*s->sensor_altitude_hae, 23456.234375, 1e-9);
  EXPECT_NEAR(*s->platform_heading, 159.9744, 0.003);
  EXPECT_NEAR(*s->platform_pitch, -0.4315251, 1e-7);  // the full-range tag 90 wins over tag 6
  EXPECT_NEAR(*s->horizontal_fov, 144.5713, 0.0014);
  EXPECT_FALSE(s->sensor_relative_elevation.has_value());
  EXPECT_FALSE(s->vertical_fov.has_value());
  EXPECT_EQ(*s->unix_time_us, 1224807209913000ull);
  const auto j = ToJson(*s);
  EXPECT_EQ(j["source"], "ST0601");
  EXPECT_FALSE(j.contains("vertical_fov"));
  EXPECT_NEAR(j["sensor_latitude"].get<double>(), 60.176822966978335, 1e-12);
}

TEST(Telemetry, InterpolatesLinearlyAndAcrossTheHeadingWrap) {
  std::vector<TelemetrySample> v = {Sample(0.0, 38.0, -77.0, 350.0), Sample(1.0, 38.001, -76.998, 10.0)};
  v[0].sensor_relative_elevation = -30;
  v[1].sensor_relative_elevation = -40;
  v[0].unix_time_us = 1000000;
  v[1].unix_time_us = 2000000;
  const auto s = InterpolateTelemetry(v, 0.25);
  ASSERT_TRUE(s);
  EXPECT_DOUBLE_EQ(s->time, 0.25);
  EXPECT_NEAR(*s->sensor_latitude, 38.00025, 1e-12);
  EXPECT_NEAR(*s->sensor_longitude, -76.9995, 1e-12);
  EXPECT_NEAR(*s->platform_heading, 355.0, 1e-9);  // through north, not through 180
  EXPECT_NEAR(*InterpolateTelemetry(v, 0.75)->platform_heading, 5.0, 1e-9);
  EXPECT_NEAR(*s->sensor_relative_elevation, -32.5, 1e-12);
  EXPECT_EQ(*s->unix_time_us, 1250000u);
}

TEST(Telemetry, LongitudeWrapsAtTheAntimeridian) {
  std::vector<TelemetrySample> v = {Sample(0, 0, 179.9, 0), Sample(1, 0, -179.9, 0)};
  EXPECT_NEAR(*InterpolateTelemetry(v, 0.25)->sensor_longitude, 179.95, 1e-9);
  EXPECT_NEAR(*InterpolateTelemetry(v, 0.75)->sensor_longitude, -179.95, 1e-9);
}

TEST(Telemetry, FieldsOnlyOneSideHasComeFromTheNearestSample) {
  std::vector<TelemetrySample> v = {Sample(0, 1, 2, 3), Sample(1, 1, 2, 3)};
  v[1].horizontal_fov = 20;
  v[1].source = "EG0104";
  EXPECT_FALSE(InterpolateTelemetry(v, 0.3)->horizontal_fov.has_value());
  EXPECT_EQ(InterpolateTelemetry(v, 0.3)->source, "ST0601");
  EXPECT_EQ(*InterpolateTelemetry(v, 0.7)->horizontal_fov, 20);
  EXPECT_EQ(InterpolateTelemetry(v, 0.7)->source, "EG0104");
}

TEST(Telemetry, ExtrapolationIsBounded) {
  std::vector<TelemetrySample> v = {Sample(1, 1, 2, 3), Sample(2, 2, 3, 4)};
  EXPECT_FALSE(InterpolateTelemetry({}, 1.0).has_value());
  EXPECT_FALSE(InterpolateTelemetry(v, 0.2).has_value());
  EXPECT_FALSE(InterpolateTelemetry(v, 2.6).has_value());
  EXPECT_DOUBLE_EQ(*InterpolateTelemetry(v, 0.6)->sensor_latitude, 1.0);
  EXPECT_DOUBLE_EQ(*InterpolateTelemetry(v, 2.4)->sensor_latitude, 2.0);
  EXPECT_DOUBLE_EQ(*InterpolateTelemetry(v, 2.0)->sensor_latitude, 2.0);
  EXPECT_DOUBLE_EQ(*InterpolateTelemetry(v, 1.5, 0.0)->sensor_latitude, 1.5);
}

}  // namespace
}  // namespace fmv3d::telemetry
