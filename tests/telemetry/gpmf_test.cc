// GPMF: the parser against the writer (exact values), against malformed bytes (never out of bounds, never a
// crash), and against GoPro's own files in ../shared/data/fmv/gopro (values from its README).
#include "fmv3d/telemetry/gpmf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>

#include "fmv3d/telemetry/gpmf_telemetry.h"
#include "fmv3d/telemetry/gpmf_writer.h"
#include "test_util.h"

namespace fmv3d::telemetry {
namespace {

gpmf::PayloadContent Content(bool gps9, size_t n = 5) {
  gpmf::PayloadContent c;
  c.gps9 = gps9;
  c.gps_dop = 1.25;
  for (size_t i = 0; i < n; ++i) {
    gpmf::GpsFix f;
    f.latitude = 33.1267701 + 1e-5 * i;
    f.longitude = -117.3273442 - 2e-5 * i;
    f.altitude = -22.959 + 0.5 * i;
    f.speed_2d = 3.5;
    f.speed_3d = 3.61;
    f.unix_seconds = 1717243200.0 + 0.1 * i;
    c.gps.push_back(f);
    const double a = 0.1 * i;
    c.orientation.push_back({std::cos(a / 2), 0, std::sin(a / 2), 0});
  }
  return c;
}

std::vector<uint8_t> ReadBytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(Gpmf, ExpandsComplexTypes) {
  EXPECT_EQ(gpmf::ExpandType("f[3]L").value(), "fffL");
  EXPECT_EQ(gpmf::ExpandType("lllllllSS").value(), "lllllllSS");
  EXPECT_FALSE(gpmf::ExpandType("f[").has_value());
  EXPECT_FALSE(gpmf::ExpandType("f[x]").has_value());
  EXPECT_FALSE(gpmf::ExpandType("[3]").has_value());
  EXPECT_FALSE(gpmf::ExpandType("f[99999]").has_value());
  EXPECT_FALSE(gpmf::ExpandType("Z").has_value());
}

TEST(Gpmf, Gps5RoundTripIsExactToTheScale) {
  const auto c = Content(false);
  const auto bytes = gpmf::EncodePayload(c);
  gpmf::ParseStats stats;
  const auto streams = gpmf::ParsePayload(bytes.data(), bytes.size(), &stats);
  EXPECT_EQ(stats.malformed, 0u);
  ASSERT_EQ(streams.size(), 2u);
  const gpmf::Stream& g = streams[0];
  EXPECT_EQ(g.key, "GPS5");
  EXPECT_EQ(g.device, "fmv3d synth");
  ASSERT_EQ(g.elements, 5u);
  ASSERT_EQ(g.samples(), 5u);
  ASSERT_EQ(g.units.size(), 5u);
  EXPECT_EQ(g.units[0], "deg");
  EXPECT_EQ(g.units[2], "m");
  EXPECT_EQ(g.gps_fix.value(), 3);
  EXPECT_DOUBLE_EQ(g.gps_dop.value(), 1.25);
  EXPECT_EQ(g.gps_utc, "240601120000.000");
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_NEAR(g.at(i, 0), c.gps[i].latitude, 0.51e-7);
    EXPECT_NEAR(g.at(i, 1), c.gps[i].longitude, 0.51e-7);
    EXPECT_NEAR(g.at(i, 2), c.gps[i].altitude, 0.51e-3);
  }
  const gpmf::Stream& o = streams[1];
  EXPECT_EQ(o.key, "CORI");
  ASSERT_EQ(o.elements, 4u);
  EXPECT_NEAR(o.at(4, 0), std::cos(0.2), 1e-4);
  EXPECT_NEAR(o.at(4, 2), std::sin(0.2), 1e-4);
}

TEST(Gpmf, Gps9ComplexStructureCarriesFixDopAndTime) {
  const auto bytes = gpmf::EncodePayload(Content(true));
  const auto streams = gpmf::ParsePayload(bytes.data(), bytes.size());
  ASSERT_FALSE(streams.empty());
  const gpmf::Stream& g = streams[0];
  EXPECT_EQ(g.key, "GPS9");
  EXPECT_EQ(g.type, "lllllllSS");
  ASSERT_EQ(g.elements, 9u);
  EXPECT_NEAR(g.at(2, 0), 33.1267901, 1e-7);
  EXPECT_NEAR(g.at(2, 7), 1.25, 1e-9);  // DOP
  EXPECT_EQ(g.at(2, 8), 3);             // fix
  // Samples at t = 0, 0.5, ... over a 2 s payload; GPS9 time: days since 2000 + seconds.
  GpmfPayload p{10.0, 2.0, bytes};
  const GpmfTelemetry t = TelemetryFromGpmf({p});
  ASSERT_EQ(t.samples.size(), 5u);
  EXPECT_DOUBLE_EQ(t.samples[1].time, 10.4);
  EXPECT_NEAR(static_cast<double>(*t.samples[2].unix_time_us), (1717243200.2) * 1e6, 1e3);
  EXPECT_NEAR(*t.samples[2].sensor_altitude_hae, -21.959, 1e-3);
  EXPECT_FALSE(t.samples[2].sensor_altitude_msl.has_value());
  EXPECT_EQ(*t.samples[2].gps_fix, 3);
  EXPECT_NEAR(*t.samples[2].camera_orientation_w, std::cos(0.1), 1e-4);
}

TEST(Gpmf, NoLockZeroAndPoorFixesAreDroppedAndCounted) {
  auto c = Content(false, 4);
  c.gps_fix = 0;  // no lock
  std::vector<GpmfPayload> payloads{{0, 1, gpmf::EncodePayload(c)}};
  c.gps_fix = 3;
  c.gps_dop = 45;  // DOP huge
  payloads.push_back({1, 1, gpmf::EncodePayload(c)});
  c.gps_dop = 1;
  for (auto& f : c.gps) f.latitude = f.longitude = 0;  // (0, 0)
  payloads.push_back({2, 1, gpmf::EncodePayload(c)});
  c = Content(false, 4);
  payloads.push_back({3, 1, gpmf::EncodePayload(c)});
  const GpmfTelemetry t = TelemetryFromGpmf(payloads);
  EXPECT_EQ(t.fixes.kept, 4u);
  EXPECT_EQ(t.fixes.rejected[static_cast<size_t>(FixRejection::kNoLock)], 4u);
  EXPECT_EQ(t.fixes.rejected[static_cast<size_t>(FixRejection::kPoorDop)], 4u);
  EXPECT_EQ(t.fixes.rejected[static_cast<size_t>(FixRejection::kZeroFix)], 4u);
  ASSERT_EQ(t.samples.size(), 4u);
  for (const auto& s : t.samples) EXPECT_GE(s.time, 3.0);
  EXPECT_EQ(t.fixes.Summary("fixes"), "12 of 16 fixes dropped: 4 (0, 0) fix, 4 no lock, 4 DOP too large");
}

TEST(Gpmf, MalformedBytesNeverReadOutOfBounds) {
  const auto good = gpmf::EncodePayload(Content(true));
  for (size_t n = 0; n <= good.size(); ++n) {
    gpmf::ParseStats stats;
    const auto streams = gpmf::ParsePayload(good.data(), n, &stats);
    for (const auto& s : streams) EXPECT_EQ(s.values.size(), s.samples() * s.elements);
  }
  size_t flagged = 0;
  for (size_t i = 0; i < good.size(); ++i) {
    for (uint8_t v : {0x00, 0x3F, 0xFF}) {
      auto bad = good;
      bad[i] = v;
      gpmf::ParseStats stats;
      const auto streams = gpmf::ParsePayload(bad.data(), bad.size(), &stats);
      flagged += stats.malformed > 0;
      (void)TelemetryFromGpmf({{0, 1, bad}});
    }
  }
  EXPECT_GT(flagged, 0u);
  // A size field pointing past the end is malformed, not followed.
  std::vector<uint8_t> lie = {'D', 'E', 'V', 'C', 0, 1, 0xFF, 0xFF, 'G', 'P', 'S', '5'};
  gpmf::ParseStats stats;
  EXPECT_TRUE(gpmf::ParsePayload(lie.data(), lie.size(), &stats).empty());
  EXPECT_EQ(stats.malformed, 1u);
}

TEST(Gpmf, OtherDevicesPositionStreamsDescribeThemselves) {
  // A device of its own (not GoPro's GPS5/9): a complex structure with TYPE, SCAL, UNIT and STNM.
  std::vector<uint8_t> strm;
  auto entry = [](std::vector<uint8_t>* out, const char* key, char type, uint8_t ssize, uint16_t repeat,
                  std::vector<uint8_t> data) {
    out->insert(out->end(), key, key + 4);
    out->push_back(static_cast<uint8_t>(type));
    out->push_back(ssize);
    out->push_back(repeat >> 8);
    out->push_back(repeat & 0xFF);
    data.resize((data.size() + 3) & ~size_t(3), 0);
    out->insert(out->end(), data.begin(), data.end());
  };
  const std::string name = "Drone position";
  entry(&strm, "STNM", 'c', 1, static_cast<uint16_t>(name.size()), {name.begin(), name.end()});
  entry(&strm, "TYPE", 'c', 1, 3, {'d', 'd', 'f'});
  entry(&strm, "UNIT", 'c', 3, 3, {'d', 'e', 'g', 'd', 'e', 'g', 'm', 0, 0});
  std::vector<uint8_t> sample;
  auto be = [&](const void* p, size_t n) {
    const auto* b = static_cast<const uint8_t*>(p);
    for (size_t i = 0; i < n; ++i) sample.push_back(b[n - 1 - i]);  // little-endian host → big endian
  };
  const double lat = 46.5, lon = 7.25;
  const float alt = 1500.5f;
  be(&lat, 8);
  be(&lon, 8);
  be(&alt, 4);
  entry(&strm, "DPOS", '?', 20, 1, sample);
  std::vector<uint8_t> devc, payload;
  entry(&devc, "DVNM", 'c', 1, 4, {'D', 'r', 'n', '1'});
  entry(&devc, "STRM", 0, 1, static_cast<uint16_t>(strm.size()), strm);
  entry(&payload, "DEVC", 0, 1, static_cast<uint16_t>(devc.size()), devc);
  const GpmfTelemetry t = TelemetryFromGpmf({{0, 1, payload}});
  ASSERT_EQ(t.samples.size(), 1u);
  EXPECT_EQ(t.samples[0].source, "GPMF-DPOS");
  EXPECT_DOUBLE_EQ(*t.samples[0].sensor_latitude, 46.5);
  EXPECT_DOUBLE_EQ(*t.samples[0].sensor_longitude, 7.25);
  EXPECT_DOUBLE_EQ(*t.samples[0].sensor_altitude_hae, 1500.5);
  EXPECT_EQ(t.devices, std::vector<std::string>{"Drn1"});
}

TEST(Gpmf, RealRawPayloads) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/gopro/hero5.raw");
  struct Case {
    const char* file;
    double lat, lon, alt;
    bool locked;  // hero6.raw states GPSF 0 (no lock) and GPSP 9999: its fixes must not be used
  };
  for (const Case& c : {Case{"hero5.raw", 33.126497, -117.327354, -20.184, true},
                        Case{"hero6.raw", 33.126554, -117.327130, -18.172, false}}) {
    const auto bytes = ReadBytes(test::SharedData() / "fmv/gopro" / c.file);
    gpmf::ParseStats stats;
    const auto streams = gpmf::ParsePayload(bytes.data(), bytes.size(), &stats);
    EXPECT_EQ(stats.malformed, 0u) << c.file;
    const gpmf::Stream* gps = nullptr;
    bool accl = false, gyro = false;
    for (const auto& s : streams) {
      if (s.key == "GPS5") gps = &s;
      accl |= s.key == "ACCL" && s.elements == 3 && s.samples() > 100;
      gyro |= s.key == "GYRO" && s.elements == 3 && s.samples() > 100;
    }
    EXPECT_TRUE(accl && gyro) << c.file;
    ASSERT_NE(gps, nullptr) << c.file;
    EXPECT_NEAR(gps->at(0, 0), c.lat, 5e-7) << c.file;
    EXPECT_NEAR(gps->at(0, 1), c.lon, 5e-7) << c.file;
    EXPECT_NEAR(gps->at(0, 2), c.alt, 5e-4) << c.file;
    const GpmfTelemetry t = TelemetryFromGpmf({{0, 1, bytes}});
    if (!c.locked) {
      EXPECT_TRUE(t.samples.empty()) << c.file;
      EXPECT_EQ(t.fixes.rejected[static_cast<size_t>(FixRejection::kNoLock)], gps->samples()) << c.file;
      continue;
    }
    EXPECT_EQ(t.fixes.kept, gps->samples()) << c.file;
    ASSERT_FALSE(t.samples.empty()) << c.file;
    EXPECT_NEAR(*t.samples[0].sensor_latitude, c.lat, 5e-7) << c.file;
    EXPECT_NEAR(*t.samples[0].sensor_altitude_hae, c.alt, 5e-4) << c.file;
  }
}

TEST(Gpmf, RealMp4Track) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/gopro/max-heromode.mp4");
  const auto path = test::SharedData() / "fmv/gopro/max-heromode.mp4";
  const auto payloads = ReadGpmfPayloads(path);
  EXPECT_GE(payloads.size(), 10u);
  const GpmfTelemetry t = TelemetryFromGpmf(payloads);
  EXPECT_EQ(t.parse.malformed, 0u);
  ASSERT_FALSE(t.samples.empty());
  const auto& s = t.samples.front();
  EXPECT_NEAR(*s.sensor_latitude, 33.126770, 5e-7);
  EXPECT_NEAR(*s.sensor_longitude, -117.327344, 5e-7);
  EXPECT_NEAR(*s.sensor_altitude_hae, -22.959, 5e-4);
  EXPECT_TRUE(s.camera_orientation_w.has_value());
  EXPECT_GT(t.stream_samples.at("CORI"), 0u);
  EXPECT_GT(t.stream_samples.at("ACCL"), 0u);
  // Samples are in time order, within the clip (10.5 s).
  for (size_t i = 1; i < t.samples.size(); ++i) EXPECT_GE(t.samples[i].time, t.samples[i - 1].time);
  EXPECT_GE(t.samples.front().time, 0);
  EXPECT_LE(t.samples.back().time, 10.6);
}

}  // namespace
}  // namespace fmv3d::telemetry
