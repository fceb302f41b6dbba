// `fmv3d klv` as a user runs it: the packets of a real stream as JSON, and the messages for files without KLV.
#include <gtest/gtest.h>

#include <algorithm>

#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d {
namespace {

TEST(KlvCli, DumpsTheStreamAsJsonWithASummary) {
  const std::string rel = "fmv/kwiver/videos/aphill_short.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  test::TempDir dir;
  const auto r =
      test::RunCli("klv '" + (test::SharedData() / rel).string() + "' -o '" + (dir / "k.json").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("stream 1: 48 KLV packets"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("bad checksum: 0"), std::string::npos) << r.err;
  const auto j = core::ReadJson(dir / "k.json");
  ASSERT_EQ(j.size(), 48u);
  EXPECT_EQ(j[0]["key"]["string"], "MISB ST0104 Universal Set");
  bool found = false;
  for (const auto& item : j[0]["value"])
    if (item["key"]["string"] == "Device Latitude") {
      found = true;
      EXPECT_NEAR(item["value"].get<double>(), 38.2523, 0.001);
    }
  EXPECT_TRUE(found);
}

TEST(KlvCli, NoKlvAndUnreadableFiles) {
  const std::string rel = "fmv/kwiver/videos/h264_no_klv.ts";
  FMV3D_REQUIRE_SHARED_DATA(rel);
  auto r = test::RunCli("klv '" + (test::SharedData() / rel).string() + "'");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out), nlohmann::json::array());
  EXPECT_NE(r.err.find("no KLV data stream"), std::string::npos) << r.err;
  r = test::RunCli("klv /nonexistent/video.ts");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/nonexistent/video.ts"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

}  // namespace
}  // namespace fmv3d
