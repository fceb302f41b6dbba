// The ST 0601 encoder against our decoder (io/klv_st0601.h), the attitude conventions, and `fmv3d synth
// --klv` read back through `fmv3d frames` / `fmv3d klv`: a synthetic flight's telemetry must decode to what
// was written, within the encodings' precision.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/synth/synth.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/klv.h"
#include "fmv3d/telemetry/klv_st0601.h"
#include "fmv3d/telemetry/klv_st0601_writer.h"
#include "fmv3d/telemetry/telemetry.h"
#include "test_util.h"

namespace fmv3d {
namespace {

using telemetry::klv::St0601Record;

St0601Record SampleRecord() {
  St0601Record r;
  r.unix_time_us = 1717243200123456ull;
  r.sensor_latitude = 38.1612345;
  r.sensor_longitude = -77.3498765;
  r.sensor_true_altitude = 321.7;
  r.sensor_ellipsoid_height = 288.2;
  r.platform_heading = 359.99;
  r.platform_pitch = -3.25;
  r.platform_roll = 12.5;
  r.sensor_relative_azimuth = -10.0;  // wraps to 350
  r.sensor_relative_elevation = -47.123;
  r.sensor_relative_roll = 1.5;
  r.horizontal_fov = 60.0;
  r.vertical_fov = 35.98;
  r.slant_range = 412.5;
  r.frame_center_latitude = 38.16;
  r.frame_center_longitude = -77.35;
  r.frame_center_elevation = 59.0;
  return r;
}

// Half a code step of each encoding: the bound a decoded value must meet.
constexpr double kLatStep = 90.0 / 2147483647.0, kLonStep = 180.0 / 2147483647.0;
constexpr double kAltStep = 19900.0 / 65535.0, kHeadingStep = 360.0 / 65535.0, kFovStep = 180.0 / 65535.0;
constexpr double kAngle32Step = 360.0 / 4294967295.0, kPitchStep = 90.0 / 2147483647.0;

TEST(KlvWriter, PacketDecodesToTheValuesWritten) {
  const St0601Record r = SampleRecord();
  const auto bytes = telemetry::klv::EncodeSt0601Packet(r);
  std::vector<telemetry::klv::Packet> packets;
  telemetry::klv::ParseStats stats;
  telemetry::klv::ParseBuffer(telemetry::klv::ByteSpan(bytes.data(), bytes.size()), &packets, &stats);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_EQ(stats.bad_checksum, 0u);
  EXPECT_EQ(stats.malformed, 0u);
  EXPECT_EQ(stats.bad_items, 0u);
  ASSERT_EQ(packets[0].standard, telemetry::klv::Standard::kSt0601);
  const auto s = telemetry::SampleFromPacket(packets[0]);
  ASSERT_TRUE(s);
  EXPECT_EQ(*s->unix_time_us, r.unix_time_us);
  EXPECT_NEAR(*s->sensor_latitude, r.sensor_latitude, 0.5 * kLatStep + 1e-12);
  EXPECT_NEAR(*s->sensor_longitude, r.sensor_longitude, 0.5 * kLonStep + 1e-12);
  EXPECT_NEAR(*s->sensor_altitude_msl, r.sensor_true_altitude, 0.5 * kAltStep);
  EXPECT_NEAR(*s->sensor_altitude_hae, *r.sensor_ellipsoid_height, 0.5 * kAltStep);
  EXPECT_NEAR(*s->platform_heading, 359.99, 0.5 * kHeadingStep);
  EXPECT_NEAR(*s->platform_pitch, r.platform_pitch, 0.5 * kPitchStep + 1e-12);
  EXPECT_NEAR(*s->platform_roll, r.platform_roll, 0.5 * kPitchStep + 1e-12);
  EXPECT_NEAR(*s->sensor_relative_azimuth, 350.0, 0.5 * kAngle32Step + 1e-12);
  EXPECT_NEAR(*s->sensor_relative_elevation, r.sensor_relative_elevation, 0.5 * 180.0 / 2147483647.0 + 1e-12);
  EXPECT_NEAR(*s->sensor_relative_roll, r.sensor_relative_roll, 0.5 * kAngle32Step + 1e-12);
  EXPECT_NEAR(*s->horizontal_fov, 60.0, 0.5 * kFovStep);
  EXPECT_NEAR(*s->vertical_fov, 35.98, 0.5 * kFovStep);
  EXPECT_NEAR(*s->slant_range, 412.5, 0.5 * 5e6 / 4294967295.0 + 1e-9);
  EXPECT_NEAR(*s->frame_center_latitude, 38.16, 0.5 * kLatStep + 1e-12);
  EXPECT_NEAR(*s->frame_center_elevation, 59.0, 0.5 * kAltStep);

  // One flipped value byte must fail the checksum.
  auto bad = bytes;
  bad[30] ^= 0x01;
  packets.clear();
  telemetry::klv::ParseStats bad_stats;
  telemetry::klv::ParseBuffer(telemetry::klv::ByteSpan(bad.data(), bad.size()), &packets, &bad_stats);
  EXPECT_TRUE(packets.empty());
  EXPECT_EQ(bad_stats.bad_checksum, 1u);
}

TEST(KlvWriter, BerAndMappingPrimitives) {
  EXPECT_EQ(telemetry::klv::EncodeBerLength(5), std::vector<uint8_t>({0x05}));
  EXPECT_EQ(telemetry::klv::EncodeBerLength(200), std::vector<uint8_t>({0x81, 0xC8}));
  EXPECT_EQ(telemetry::klv::EncodeBerLength(256), std::vector<uint8_t>({0x82, 0x01, 0x00}));
  EXPECT_EQ(telemetry::klv::EncodeBerOid(127), std::vector<uint8_t>({0x7F}));
  EXPECT_EQ(telemetry::klv::EncodeBerOid(129), std::vector<uint8_t>({0x81, 0x01}));
  // Round trip through the decoder's mappings at the ends and in the middle of each range.
  for (double v : {-900.0, 0.0, 123.4, 19000.0})
    EXPECT_NEAR(telemetry::klv::MapUnsigned(telemetry::klv::EncodeUnsignedMapped(v, 2, -900, 19000), 2, -900, 19000), v,
                0.5 * kAltStep);
  for (double v : {-90.0, -12.345678, 0.0, 90.0})
    EXPECT_NEAR(*telemetry::klv::MapSigned(telemetry::klv::EncodeSignedMapped(v, 4, 90), 4, 90), v,
                0.5 * kLatStep + 1e-12);
  // The reserved "error" code is never produced.
  EXPECT_EQ(telemetry::klv::EncodeSignedMapped(-90, 4, 90), -2147483647);
  EXPECT_THROW(telemetry::klv::EncodeSignedMapped(90.001, 4, 90), Error);
  EXPECT_THROW(telemetry::klv::EncodeUnsignedMapped(std::nan(""), 2, 0, 1), Error);
  St0601Record r = SampleRecord();
  r.sensor_latitude = 91;
  EXPECT_THROW(telemetry::klv::EncodeSt0601Packet(r), Error);
  r = SampleRecord();
  r.sensor_true_altitude = 25000;
  EXPECT_THROW(telemetry::klv::EncodeSt0601Packet(r), Error);
}

TEST(KlvWriter, AttitudeSplitReproducesTheCameraRotation) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Matrix3d R = Eigen::Quaterniond{u(rng), u(rng), u(rng), u(rng)}.normalized().toRotationMatrix();
    const double heading = 180 * u(rng) + 180, pitch = 20 * u(rng), roll = 30 * u(rng);
    const auto a = telemetry::St0601FromCameraToEnu(R, heading, pitch, roll);
    EXPECT_TRUE((telemetry::CameraToEnuFromSt0601(a) - R).norm() < 1e-9) << i;
  }
  // A nadir camera on a platform flying north, image top forward: relative elevation -90°.
  Eigen::Matrix3d nadir;  // columns: camera x (east), y (south), z (down) in ENU
  nadir << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  const auto a = telemetry::St0601FromCameraToEnu(nadir, 0, 0, 0);
  EXPECT_NEAR(a.sensor_relative_elevation, -90, 1e-6);
  // A camera looking level due east from a north-heading platform: azimuth 90°, elevation 0, roll 0.
  Eigen::Matrix3d east;  // x = south, y = down, z = east
  east << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const auto b = telemetry::St0601FromCameraToEnu(east, 0, 0, 0);
  EXPECT_NEAR(b.sensor_relative_azimuth, 90, 1e-9);
  EXPECT_NEAR(b.sensor_relative_elevation, 0, 1e-9);
  EXPECT_NEAR(std::fmod(b.sensor_relative_roll + 180, 360) - 180, 0, 1e-9);
}

TEST(SynthGeodesy, EnuRoundTripAndKnownValues) {
  const synth::GeoPoint o{38.16, -77.35, 60};
  for (const Eigen::Vector3d& enu :
       {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1000, -2000, 300), Eigen::Vector3d(-50000, 40000, 5000)}) {
    const auto g = synth::EnuToGeodetic(enu, o);
    EXPECT_LT((synth::GeodeticToEnu(g, o) - enu).norm(), 1e-6);
  }
  // 1 km north is 1000 / (M + h) radians of latitude (M: meridian radius of curvature at 38.16°).
  const auto n = synth::EnuToGeodetic({0, 1000, 0}, o);
  const double sl = std::sin(38.16 * M_PI / 180), e2 = 0.0066943799901413165;
  const double m = 6378137.0 * (1 - e2) / std::pow(1 - e2 * sl * sl, 1.5);
  EXPECT_NEAR((n.lat - 38.16) * M_PI / 180 * (m + 60), 1000, 0.01);
  // Earth curvature: 1 km away the ground plane lies ~7.8 cm above the ellipsoid.
  EXPECT_NEAR(n.alt - 60, 0.078, 0.003);
}

// A short --klv flight: the video's KLV stream and frames.json carry the telemetry the synth wrote.
TEST(SynthKlv, TelemetryRoundTripsThroughTheVideoAndFramesStage) {
  test::TempDir dir("synth-klv");
  synth::SynthOptions o;
  o.scene = synth::SceneKind::kBuilding;
  o.flight.frames = 12;
  o.width = 192;
  o.height = 112;
  o.format = synth::OutputFormat::kTs;
  o.fps = 10;
  o.klv = true;
  o.klv_options.geoid_undulation = -33.87;  // EGM96 at the default origin: MSL heights are ellipsoidal + 33.87 m
  o.truth_points = 100;
  o.write_scene = false;
  o.render.supersample = 1;
  o.detail = 0.25;
  o.output = dir.path();
  const auto result = synth::RunSynth(o);
  ASSERT_EQ(result.klv.size(), 12u);

  // truth.json states the origin.
  nlohmann::json truth;
  std::ifstream(dir / "truth.json") >> truth;
  EXPECT_DOUBLE_EQ(truth.at("geo_origin").at("lat").get<double>(), o.klv_options.origin.lat);
  EXPECT_DOUBLE_EQ(truth.at("geo_origin").at("lon").get<double>(), o.klv_options.origin.lon);
  EXPECT_DOUBLE_EQ(truth.at("geo_origin").at("alt").get<double>(), o.klv_options.origin.alt);

  // The stream: one packet per frame, at the frame's time, decoding to what was written.
  telemetry::TelemetryStats stats;
  const auto samples = telemetry::ReadVideoTelemetry(dir / "flight.ts", &stats);
  EXPECT_EQ(stats.klv.bad_checksum, 0u);
  EXPECT_EQ(stats.klv.malformed, 0u);
  ASSERT_EQ(samples.size(), 12u);
  for (size_t k = 0; k < samples.size(); ++k) {
    const auto& s = samples[k];
    const auto& r = result.klv[k];
    EXPECT_NEAR(s.time, k / o.fps, 1e-3) << k;
    EXPECT_NEAR(*s.sensor_latitude, r.sensor_latitude, 0.5 * kLatStep + 1e-12) << k;
    EXPECT_NEAR(*s.sensor_longitude, r.sensor_longitude, 0.5 * kLonStep + 1e-12) << k;
    EXPECT_NEAR(*s.sensor_altitude_msl, r.sensor_true_altitude, 0.5 * kAltStep) << k;
    EXPECT_NEAR(*s.horizontal_fov, 60.0, 0.5 * kFovStep) << k;
    // Both datums, for the sensor and the frame centre (tags 15/75, 25/78), apart by the undulation.
    ASSERT_TRUE(s.sensor_altitude_hae && s.frame_center_hae && s.frame_center_elevation) << k;
    EXPECT_NEAR(*s.sensor_altitude_hae - *s.sensor_altitude_msl, -33.87, kAltStep) << k;
    EXPECT_NEAR(*s.frame_center_hae - *s.frame_center_elevation, -33.87, kAltStep) << k;
  }
  // The noisy positions scatter around the truth by about the stated GPS noise (3 m per axis).
  double sq = 0;
  for (size_t k = 0; k < samples.size(); ++k) {
    const synth::GeoPoint g{*samples[k].sensor_latitude, *samples[k].sensor_longitude, *samples[k].sensor_altitude_hae};
    const Eigen::Vector3d enu = synth::GeodeticToEnu(g, o.klv_options.origin);
    sq += (enu - result.truth.images.at(k + 1).pose.Centre()).squaredNorm();
  }
  const double rms_per_axis = std::sqrt(sq / (3 * samples.size()));
  EXPECT_GT(rms_per_axis, 1.5);
  EXPECT_LT(rms_per_axis, 5.0);

  // `fmv3d frames` attaches them per kept frame; `fmv3d klv` dumps 12 packets.
  const auto cli = test::RunCli("frames " + (dir / "flight.ts").string() + " --all-frames -o " + (dir / "ws").string());
  ASSERT_EQ(cli.exit_code, 0) << cli.err;
  const auto index = io::ReadFramesIndex(dir / "ws/frames/frames.json");
  ASSERT_EQ(index.frames.size(), 12u);
  for (const auto& f : index.frames) {
    ASSERT_TRUE(f.telemetry.has_value()) << f.name;
    const auto& r = result.klv.at(f.frame_index);
    EXPECT_NEAR(f.telemetry->sensor_latitude.value_or(NAN), r.sensor_latitude, 0.5 * kLatStep + 1e-9) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_longitude.value_or(NAN), r.sensor_longitude, 0.5 * kLonStep + 1e-9) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_altitude_msl.value_or(NAN), r.sensor_true_altitude, 0.5 * kAltStep + 1e-6)
        << f.name;
  }
  const auto dump = test::RunCli("klv " + (dir / "flight.ts").string());
  ASSERT_EQ(dump.exit_code, 0) << dump.err;
  EXPECT_NE(dump.out.find("Sensor Latitude"), std::string::npos);
}

TEST(SynthKlv, NeedsTransportStream) {
  synth::SynthOptions o;
  o.klv = true;
  o.format = synth::OutputFormat::kMp4;
  o.output = "/nonexistent";
  EXPECT_THROW(o.Check(), Error);
}

}  // namespace
}  // namespace fmv3d
