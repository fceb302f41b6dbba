// `fmv3d manual check WS`: both manual files validated against the workspace's frames, every problem listed,
// exit 1 when any; --json for the console's server; absent files are not errors.
#include "fmv3d/pipeline/manual_check.h"

#include <gtest/gtest.h>

#include "fmv3d/core/files.h"
#include "fmv3d/io/frames_index.h"
#include "test_util.h"

namespace fmv3d::pipeline {
namespace {

void MakeWorkspace(const std::filesystem::path& ws) {
  io::FramesIndex index;
  io::CameraPrior c;
  c.camera = core::Camera::Pinhole(640, 360, 500);
  c.prior_source = fmv3d::io::ParsePriorSource("guess");
  index.cameras.push_back(c);
  for (const char* name : {"a.png", "b.png"}) {
    io::FrameRecord f;
    f.name = name;
    index.frames.push_back(f);
  }
  core::EnsureDirectory(ws / "frames");
  io::WriteFramesIndex(index, ws / "frames/frames.json");
}

TEST(ManualCheck, ValidInvalidAndAbsent) {
  test::TempDir dir("fmv3d-manual-check");
  const auto ws = dir / "ws";
  MakeWorkspace(ws);
  auto r = CheckManualInputs(ws);
  EXPECT_FALSE(r.tiepoints.present);
  EXPECT_FALSE(r.gcp.present);
  EXPECT_TRUE(r.ok());
  core::WriteTextFile(ws / "manual/tiepoints.json",
                      R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t", "observations":
                          [{"frame": "a.png", "x": 10, "y": 10}, {"frame": "b.png", "x": 12, "y": 11}]}]})");
  core::WriteTextFile(ws / "manual/gcp_list.txt",
                      "EPSG:32632\n500000 5200000 300 10 20 a.png g\n"
                      "500000 5200000 300 11 21 b.png g\n");
  r = CheckManualInputs(ws);
  EXPECT_TRUE(r.tiepoints.valid());
  EXPECT_TRUE(r.gcp.valid());
  EXPECT_EQ(r.tie_points, 1u);
  EXPECT_EQ(r.gcp_points, 1u);
  auto cli = test::RunCli("manual check " + ws.string());
  EXPECT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_NE(cli.out.find("1 tie points"), std::string::npos) << cli.out;

  core::WriteTextFile(ws / "manual/tiepoints.json",
                      R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t", "observations":
                          [{"frame": "a.png", "x": 10, "y": 10}, {"frame": "zz.png", "x": 12, "y": 11}]},
                          {"id": "u", "observations": [{"frame": "a.png", "x": 900, "y": 10}]}]})");
  core::WriteTextFile(ws / "manual/gcp_list.txt", "EPSG:999999\n1 2\n");
  r = CheckManualInputs(ws);
  EXPECT_FALSE(r.ok());
  ASSERT_EQ(r.tiepoints.errors.size(), 3u) << r.ToJson().dump(2);
  EXPECT_EQ(r.tiepoints.errors[0],
            "tiepoints.json: tie point \"u\": has 1 observation(s); a tie point needs ≥ 2 "
            "(in different frames)");
  ASSERT_EQ(r.gcp.errors.size(), 2u) << r.ToJson().dump(2);
  EXPECT_NE(r.gcp.errors[0].find("gcp_list.txt:1: unknown CRS \"EPSG:999999\""), std::string::npos);
  EXPECT_NE(r.gcp.errors[1].find("gcp_list.txt:2: expected geo_x"), std::string::npos);
  cli = test::RunCli("manual check " + ws.string() + " --json");
  EXPECT_EQ(cli.exit_code, 1);
  const auto j = nlohmann::json::parse(cli.out);
  EXPECT_FALSE(j.at("ok").get<bool>());
  EXPECT_EQ(j.at("tiepoints").at("errors").size(), 3u);
  EXPECT_FALSE(j.at("gcp").at("valid").get<bool>());
  cli = test::RunCli("manual check " + ws.string());
  EXPECT_EQ(cli.exit_code, 1);
  EXPECT_NE(cli.err.find("zz.png\" is not in frames/frames.json"), std::string::npos) << cli.err;
}

}  // namespace
}  // namespace fmv3d::pipeline
