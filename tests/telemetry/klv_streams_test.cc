// KLV in the real KWIVER test streams (../shared/data/fmv/kwiver).
//
// Note on klv_gold.json: it is the golden output of KWIVER's JSON serializer test (hand-made packets:
// "Bob", VMTI, weapons stores, ...), NOT the content of {h264,h265,mpeg2}_klv.ts (those hold 30 ST 0601
// packets built on the standard's example packet: "MISSION01", "AF-101", ...). So the streams are checked
// against the decimal values of the ST 0601 example, and the gold is used for what it does state: the
// names of keys, tags and enumerations, and packets rebuilt from its values (klv_parse_test.cc).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/telemetry/klv_eg0104.h"
#include "fmv3d/telemetry/klv_st0102.h"
#include "fmv3d/telemetry/klv_st0601.h"
#include "fmv3d/telemetry/telemetry.h"
#include "test_util.h"

namespace fmv3d::telemetry {
namespace {

const char* kVideos = "fmv/kwiver/videos";

struct Expected {
  uint64_t tag;
  double value;
  double tol;  // about half the encoding's resolution, or the precision the standard prints
};

// ST 0601 example packet (decimal values as the standard lists them) -- the first packet of each stream.
const Expected kExample[] = {
    {5, 159.9744, 0.003},
    {8, 147, 0},
    {9, 159, 0},
    {13, 60.176822966978335, 1e-9},
    {14, 128.42675904204452, 1e-9},
    {15, 14190.72, 0.16},
    {16, 144.5713, 0.0014},
    {17, 152.6436, 0.0014},
    {18, 160.71921143697557, 1e-9},
    {19, -168.79232483394085, 1e-9},
    {20, 176.86543764939194, 1e-9},
    {21, 68590.98, 0.005},
    {22, 722.8199, 0.08},
    {23, -10.542388633146132, 1e-9},
    {24, 29.157890122923014, 1e-9},
    {25, 3216.037, 0.16},
    {35, 235.924, 0.003},
    {36, 69.80392, 0.2},
    {37, 3725.185, 0.04},
    {38, 14818.68, 0.16},
    {39, 84, 0},
    {40, -79.16385, 1e-5},
    {41, 166.400812, 1e-5},
    {42, 18389.05, 0.16},
    {43, 6, 0},
    {44, 30, 0},
    {45, 425.215, 0.04},
    {46, 608.9231, 0.04},
    {47, 49, 0},
    {49, 1191.958, 0.04},
    {55, 50.58824, 0.2},
    {56, 140, 0},
    {57, 3506979.0316, 0.0012},
    {58, 6420.539, 0.08},
    {62, 1743, 0},
    {64, 311.8682, 0.003},
    {96, 13898.5, 0.25},
    {103, 23456.24, 0.01},
    {104, 23456.24, 0.01},
    {105, 23456.24, 0.01},
    {109, 1.625, 0.002},
    {110, 19887, 0},
    {111, 3000, 0},
    {112, 125, 0.008},
    {113, 2150, 0.008},
    {114, 2154.5, 0.008},
    {117, 1, 0.03},
    {118, 0.00415, 0.0001},
    {119, -50, 0.03},
    {120, 72, 0.004},
    {132, 2400, 0.02},
    {133, 10000, 0},
    {134, 55, 0.004},
};

struct Strings {
  uint64_t tag;
  const char* value;
};
const Strings kExampleStrings[] = {{3, "MISSION01"}, {4, "AF-101"},          {10, "MQ1-B"},
                                   {11, "EO"},       {12, "Geodetic WGS84"}, {59, "TOP GUN"},
                                   {70, "APACHE"},   {106, "BLUE"},          {107, "BASE01"},
                                   {108, "HOME"},    {129, "A123"},          {135, "Frequency Modulation"}};

class KlvStreams : public ::testing::TestWithParam<const char*> {};

TEST_P(KlvStreams, DecodeToTheSt0601ExampleValues) {
  const std::string rel = std::string(kVideos) + "/" + GetParam();
  FMV3D_REQUIRE_SHARED_DATA(rel);
  TelemetryStats stats;
  const auto packets = ReadVideoKlv(test::SharedData() / rel, &stats);
  ASSERT_EQ(packets.size(), 30u);
  EXPECT_EQ(stats.klv.bad_checksum, 0u);
  EXPECT_EQ(stats.klv.malformed, 0u);
  EXPECT_EQ(stats.klv.bad_items, 0u);
  ASSERT_EQ(stats.packets_per_stream.size(), 1u);
  EXPECT_EQ(stats.packets_per_stream[0].second, 30u);

  const auto& p = packets[0];
  EXPECT_EQ(p.standard, klv::Standard::kSt0601);
  EXPECT_EQ(p.items.size(), 140u);
  EXPECT_EQ(p.Find(2)->value.get<uint64_t>(), 1224807209913000ull);  // Oct 24 2008 00:13:29.913
  for (const auto& e : kExample) {
    const auto* it = p.Find(e.tag);
    ASSERT_NE(it, nullptr) << "tag " << e.tag;
    ASSERT_TRUE(it->value.is_number()) << "tag " << e.tag << ": " << it->value.dump();
    EXPECT_NEAR(it->value.get<double>(), e.value, e.tol) << "tag " << e.tag << " " << it->name;
  }
  for (const auto& s : kExampleStrings) EXPECT_EQ(p.Find(s.tag)->value, s.value) << "tag " << s.tag;
  // Enumerations and the nested ST 0102 security set.
  EXPECT_EQ(p.Find(34)->value["string"], "Icing Detected");
  EXPECT_EQ(p.Find(63)->value["string"], "Medium");
  EXPECT_EQ(p.Find(77)->value["string"], "Operational");
  const auto& sec = p.Find(48)->value;
  ASSERT_TRUE(sec.is_array());
  EXPECT_EQ(sec[0]["value"]["string"], "Unclassified");
  // The full-range pitch/roll (tags 90/91) agree with the short ones (6/7) within the short resolution.
  EXPECT_NEAR(p.Find(90)->value.get<double>(), p.Find(6)->value.get<double>(), 20.0 / 32767);
  EXPECT_NEAR(p.Find(91)->value.get<double>(), p.Find(7)->value.get<double>(), 50.0 / 32767);

  // Every packet: increasing precision timestamps 1/30 s apart, positions near the example's.
  const auto samples = ReadVideoTelemetry(test::SharedData() / rel);
  ASSERT_EQ(samples.size(), 30u);
  for (size_t i = 0; i < samples.size(); ++i) {
    ASSERT_TRUE(samples[i].sensor_latitude && samples[i].unix_time_us) << i;
    EXPECT_NEAR(*samples[i].sensor_latitude, 60.1768, 0.01) << i;
    EXPECT_NEAR(*samples[i].sensor_longitude, 128.4268, 0.01) << i;
    if (i) {
      EXPECT_GE(samples[i].time, samples[i - 1].time);
      EXPECT_NEAR(double(*samples[i].unix_time_us - *samples[i - 1].unix_time_us), 33333, 2) << i;
    }
  }
}

TEST_P(KlvStreams, AllThreeCodecsCarryTheSameKlv) {
  const std::string rel = std::string(kVideos) + "/" + GetParam();
  const std::string ref = std::string(kVideos) + "/h264_klv.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  FMV3D_REQUIRE_SHARED_DATA(ref);
  const auto a = ReadVideoKlv(test::SharedData() / rel);
  const auto b = ReadVideoKlv(test::SharedData() / ref);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(klv::ToJson(a[i])["value"], klv::ToJson(b[i])["value"]) << i;
}

INSTANTIATE_TEST_SUITE_P(Codecs, KlvStreams, ::testing::Values("h264_klv.ts", "h265_klv.ts", "mpeg2_klv.ts"));

TEST(KlvStreams, AphillYields300Eg0104PacketsNearTheSite) {
  const std::string rel = std::string(kVideos) + "/aphill_klv_10s.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  TelemetryStats stats;
  const auto samples = ReadVideoTelemetry(test::SharedData() / rel, &stats);
  ASSERT_EQ(samples.size(), 300u);
  EXPECT_EQ(stats.klv.malformed + stats.klv.bad_checksum, 0u);
  double lat_sum = 0, lon_sum = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    const auto& s = samples[i];
    EXPECT_EQ(s.source, "EG0104");
    ASSERT_TRUE(s.sensor_latitude && s.sensor_longitude && s.sensor_altitude_msl && s.unix_time_us) << i;
    EXPECT_NEAR(*s.sensor_latitude, 38.16, 0.05) << i;
    EXPECT_NEAR(*s.sensor_longitude, -77.35, 0.05) << i;
    EXPECT_GT(*s.sensor_altitude_msl, 100.0);
    EXPECT_LT(*s.sensor_altitude_msl, 10000.0);
    ASSERT_TRUE(s.horizontal_fov && s.platform_heading && s.sensor_relative_azimuth);
    EXPECT_GE(*s.platform_heading, 0.0);
    EXPECT_LT(*s.platform_heading, 360.0);
    EXPECT_GE(*s.sensor_relative_azimuth, 0.0);
    EXPECT_LT(*s.sensor_relative_azimuth, 360.0);
    EXPECT_GT(*s.horizontal_fov, 0.0);
    EXPECT_LT(*s.horizontal_fov, 90.0);
    lat_sum += *s.sensor_latitude;
    lon_sum += *s.sensor_longitude;
    if (i) {
      // 30 packets per second in presentation time and in the embedded UTC timestamps.
      EXPECT_NEAR(s.time - samples[i - 1].time, 1.0 / 29.97, 0.002) << i;
      EXPECT_GT(*s.unix_time_us, *samples[i - 1].unix_time_us) << i;
      // A plane at < 100 m/s moves < 4 m (~4e-5 deg) between packets.
      EXPECT_LT(std::abs(*s.sensor_latitude - *samples[i - 1].sensor_latitude), 4e-5) << i;
    }
  }
  EXPECT_NEAR(lat_sum / 300, 38.16, 0.02);
  EXPECT_NEAR(lon_sum / 300, -77.35, 0.02);
  EXPECT_NEAR(samples.back().time - samples.front().time, 299 / 29.97, 0.01);
}

TEST(KlvStreams, AphillShortYields48Packets) {
  const std::string rel = std::string(kVideos) + "/aphill_short.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  const auto samples = ReadVideoTelemetry(test::SharedData() / rel);
  ASSERT_EQ(samples.size(), 48u);
  // Another part of the same flight, ~10 km north of the 10 s clip's start.
  for (const auto& s : samples) {
    EXPECT_NEAR(*s.sensor_latitude, 38.2523, 0.001);
    EXPECT_NEAR(*s.sensor_longitude, -77.367, 0.002);
  }
}

TEST(KlvStreams, NoKlvStreamGivesAnEmptyList) {
  const std::string rel = std::string(kVideos) + "/h264_no_klv.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  TelemetryStats stats;
  EXPECT_TRUE(ReadVideoTelemetry(test::SharedData() / rel, &stats).empty());
  EXPECT_TRUE(stats.packets_per_stream.empty());
}

TEST(KlvStreams, UnreadableFileThrowsANamedError) {
  test::TempDir dir;
  core::WriteTextFile(dir / "junk.ts", "this is not a video");
  try {
    ReadVideoKlv(dir / "junk.ts");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("junk.ts"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadVideoKlv(dir / "missing.ts"), Error);
}

// The names klv_gold.json gives to keys, tags and enumeration values are the ones we print.
TEST(KlvGold, NamesOfKeysTagsAndEnumsMatch) {
  const std::string rel = "fmv/kwiver/klv_gold.json";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  // KWIVER writes non-finite doubles as bare -Infinity / Infinity / NaN, which is not JSON.
  std::string text = core::ReadTextFile(test::SharedData() / rel);
  for (const std::string bad : {"-Infinity", "Infinity", "NaN"})
    for (size_t at = text.find(": " + bad); at != std::string::npos; at = text.find(": " + bad))
      text.replace(at, bad.size() + 2, ": null");
  const auto gold = nlohmann::json::parse(text);
  auto key_of = [](const nlohmann::json& k) {
    std::string hex = k["hex"];
    hex.erase(std::remove(hex.begin(), hex.end(), ' '), hex.end());
    klv::UlKey key{};
    for (size_t i = 0; i < 16; ++i) key[i] = static_cast<uint8_t>(std::stoi(hex.substr(2 * i, 2), nullptr, 16));
    return key;
  };
  size_t checked_tags = 0, checked_enums = 0;
  for (const auto& packet : gold) {
    const auto key = key_of(packet["key"]);
    EXPECT_EQ(klv::KnownKeyName(key), packet["key"]["string"]);
    const std::string name = packet["key"]["string"];
    for (const auto& item : packet["value"]) {
      if (name == "MISB ST0104 Universal Set") {
        EXPECT_EQ(klv::Eg0104KeyName(key_of(item["key"])), item["key"]["string"]);
        ++checked_tags;
        continue;
      }
      if (name != "MISB ST0601 Local Set" && name != "MISB ST0102 Local Set") continue;
      const uint64_t tag = item["key"]["integer"];
      const bool is0601 = name == "MISB ST0601 Local Set";
      EXPECT_EQ(is0601 ? klv::St0601TagName(tag) : klv::St0102TagName(tag), item["key"]["string"]) << tag;
      ++checked_tags;
      const auto& v = item["value"];
      if (v.is_object() && v.contains("integer") && v.contains("string") && v.size() == 2) {
        const std::string ours =
            is0601 ? klv::St0601EnumName(tag, v["integer"]) : klv::St0102EnumName(tag, v["integer"]);
        if (is0601 && ours.empty()) continue;  // a pack we keep raw (e.g. tag 47 flags) - not an enumeration here
        EXPECT_EQ(ours, v["string"]) << "tag " << tag;
        ++checked_enums;
      }
    }
  }
  EXPECT_GE(checked_tags, 30u);
  EXPECT_GE(checked_enums, 7u);
}

}  // namespace
}  // namespace fmv3d::telemetry
