#include "fmv3d/io/frames_index.h"

#include <gtest/gtest.h>

#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

TEST(FramesIndex, PriorSourceSpellingsRoundTrip) {
  const std::pair<const char*, PriorSource> cases[] = {
      {"", {PriorKind::kNone, ""}},
      {"guess", {PriorKind::kGuess, ""}},
      {"exif", {PriorKind::kExif, ""}},
      {"telemetry-hfov", {PriorKind::kTelemetryHfov, ""}},
      {"sensor-db:DJI Phantom 4 Pro", {PriorKind::kSensorDb, "DJI Phantom 4 Pro"}},
      {"calibration:/data/cam.json", {PriorKind::kCalibration, "/data/cam.json"}},
      {"calibration:", {PriorKind::kCalibration, ""}},
      {"user", {PriorKind::kOther, "user"}},            // an unknown spelling is kept verbatim
      {"Guess", {PriorKind::kOther, "Guess"}},          // spellings are case-sensitive
      {"sensor-db", {PriorKind::kOther, "sensor-db"}},  // the prefix needs its colon
  };
  for (const auto& [name, source] : cases) {
    const PriorSource parsed = ParsePriorSource(name);
    EXPECT_EQ(parsed.kind, source.kind) << name;
    EXPECT_EQ(parsed.detail, source.detail) << name;
    EXPECT_EQ(PriorSourceName(parsed), name);
  }
}

TEST(FramesIndex, PriorSourceIsWrittenAsFramesJsonSpellsIt) {
  const test::TempDir dir("frames_index");
  FramesIndex index;
  CameraPrior c;
  c.camera = core::Camera::Pinhole(640, 480, 700);
  c.camera.id = 1;
  c.prior_source = {PriorKind::kSensorDb, "lab cam"};
  c.source = "flight.ts";
  index.cameras.push_back(c);
  WriteFramesIndex(index, dir / "frames.json");
  EXPECT_EQ(core::ReadJson(dir / "frames.json").at("cameras").at(0).at("prior_source"), "sensor-db:lab cam");
  const FramesIndex back = ReadFramesIndex(dir / "frames.json");
  ASSERT_EQ(back.cameras.size(), 1u);
  EXPECT_EQ(back.cameras[0].prior_source.kind, PriorKind::kSensorDb);
  EXPECT_EQ(back.cameras[0].prior_source.detail, "lab cam");
}

}  // namespace
}  // namespace fmv3d::io
