// Ingestion attaches each video keyframe's KLV telemetry, interpolated at the frame's time, to frames.json.
#include <gtest/gtest.h>

#include <cmath>

#include "fmv3d/ingest/frames.h"
#include "fmv3d/io/frames_index.h"
#include "test_util.h"

namespace fmv3d::ingest {
namespace {

TEST(FramesTelemetry, KlvPositionsReachFramesJson) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos/aphill_klv_10s.ts");
  test::TempDir ws;
  IngestOptions options;
  options.workspace = ws.path();
  const auto index = IngestFrames({test::SharedData() / "fmv/kwiver/videos/aphill_klv_10s.ts"}, options);
  ASSERT_FALSE(index.frames.empty());
  for (const auto& f : index.frames) {
    ASSERT_TRUE(f.telemetry.has_value()) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_latitude.value_or(NAN), 38.16, 0.05) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_longitude.value_or(NAN), -77.35, 0.05) << f.name;
  }
  const auto back = io::ReadFramesIndex(ws / "frames/frames.json");
  EXPECT_EQ(back.frames.front().telemetry, index.frames.front().telemetry);
  // The stream's sensor HFOV (0.8°) is the focal prior: (360 / 2) / tan(0.4°) = 25,783 px, not the guess.
  ASSERT_EQ(index.cameras.size(), 1u);
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras[0].prior_source), "telemetry-hfov");
  EXPECT_NEAR(index.cameras[0].camera.f, 180 / std::tan(0.4 * M_PI / 180), 30);
}

TEST(FramesTelemetry, VideoWithoutKlvHasNone) {
  FMV3D_REQUIRE_SHARED_DATA("fmv/kwiver/videos/h264_no_klv.ts");
  test::TempDir ws;
  IngestOptions options;
  options.workspace = ws.path();
  const auto index = IngestFrames({test::SharedData() / "fmv/kwiver/videos/h264_no_klv.ts"}, options);
  ASSERT_FALSE(index.frames.empty());
  for (const auto& f : index.frames) EXPECT_FALSE(f.telemetry.has_value()) << f.name;
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras.at(0).prior_source), "guess");
}

}  // namespace
}  // namespace fmv3d::ingest
