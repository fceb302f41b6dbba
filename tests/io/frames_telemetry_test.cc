// Ingestion attaches each video keyframe's KLV telemetry, interpolated at the frame's time, to frames.json.
#include <gtest/gtest.h>

#include "fmv3d/io/frames.h"
#include "fmv3d/io/frames_index.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

TEST(FramesTelemetry, KlvPositionsReachFramesJson) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos/aphill_klv_10s.ts");
  test::TempDir ws;
  IngestOptions options;
  options.workspace = ws.path();
  const auto index = IngestFrames({test::SharedData() / "fmv/kwiver/videos/aphill_klv_10s.ts"}, options);
  ASSERT_FALSE(index.frames.empty());
  for (const auto& f : index.frames) {
    ASSERT_TRUE(f.telemetry.is_object()) << f.name;
    EXPECT_NEAR(f.telemetry.at("sensor_latitude").get<double>(), 38.16, 0.05) << f.name;
    EXPECT_NEAR(f.telemetry.at("sensor_longitude").get<double>(), -77.35, 0.05) << f.name;
  }
  const auto back = ReadFramesIndex(ws / "frames/frames.json");
  EXPECT_EQ(back.frames.front().telemetry, index.frames.front().telemetry);
}

TEST(FramesTelemetry, VideoWithoutKlvHasNone) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos/h264_no_klv.ts");
  test::TempDir ws;
  IngestOptions options;
  options.workspace = ws.path();
  const auto index = IngestFrames({test::SharedData() / "fmv/kwiver/videos/h264_no_klv.ts"}, options);
  ASSERT_FALSE(index.frames.empty());
  for (const auto& f : index.frames) EXPECT_TRUE(f.telemetry.is_null()) << f.name;
}

}  // namespace
}  // namespace fmv3d::io
