// `spatial` pair selection from per-frame telemetry in frames.json: a nadir lawn-mower grid flight (DJI-style
// gimbal angles, relative altitude) and an oblique KLV-style orbit with frame-centre coordinates.
#include "fmv3d/features/spatial_pairs.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "fmv3d/io/frames_index.h"
#include "test_util.h"

namespace fmv3d::features {
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = M_PI / 180.0;
constexpr double kLat0 = 47.0, kLon0 = 8.0;

double LatOf(double north_m) { return kLat0 + north_m / 6378137.0 / kDeg; }
double LonOf(double east_m) { return kLon0 + east_m / (6378137.0 * std::cos(kLat0 * kDeg)) / kDeg; }

// 3 lines of 8 nadir frames, 100 m above ground, 60° HFOV (footprint half-width ≈ 58 m, radius ≈ 58 m with the
// 4:3 frame): 30 m spacing along a line, 200 m between lines (no overlap across lines). Written to frames.json
// and read back, as the match stage does.
io::FramesIndex GridFlight(const fs::path& dir, bool with_telemetry_on_all) {
  io::FramesIndex index;
  io::CameraPrior cam;
  cam.camera = core::Camera::Pinhole(800, 600, 400 / std::tan(30 * kDeg));
  cam.prior_source = fmv3d::io::ParsePriorSource("guess");
  index.cameras.push_back(cam);
  for (int line = 0; line < 3; ++line)
    for (int k = 0; k < 8; ++k) {
      io::FrameRecord f;
      f.name = "grid-" + std::to_string(line * 8 + k) + ".png";
      f.frame_index = line * 8 + k;
      const double east = 30.0 * (line % 2 ? 7 - k : k), north = 200.0 * line;
      if (with_telemetry_on_all || (line * 8 + k) % 5 != 0)
        f.telemetry = core::TelemetryFromJson({{"time", 0.0},
                                               {"source", "DJI-SRT"},
                                               {"sensor_latitude", LatOf(north)},
                                               {"sensor_longitude", LonOf(east)},
                                               {"sensor_relative_altitude", 100.0},
                                               {"gimbal_yaw", 90.0},
                                               {"gimbal_pitch", -90.0}});
      index.frames.push_back(f);
    }
  io::WriteFramesIndex(index, dir / "frames.json");
  return io::ReadFramesIndex(dir / "frames.json");
}

TEST(SpatialPairs, NadirGridPairsOverlappingFootprintsOnly) {
  test::TempDir tmp;
  const auto index = GridFlight(tmp.path(), true);
  const auto fps = FootprintsFromTelemetry(index);
  ASSERT_EQ(fps.size(), 24u);
  for (const auto& f : fps) {
    ASSERT_TRUE(f.valid) << f.why_invalid;
    EXPECT_NEAR(f.radius, 100 * std::tan(30 * kDeg), 1.0);  // nadir: the across half-extent
  }
  // Frame 1 is 30 m east of frame 0 (nadir: the footprint centre is under the sensor).
  EXPECT_NEAR((fps[1].centre - fps[0].centre).norm(), 30.0, 0.1);
  const auto pairs = SpatialPairs(fps, 0.8, 30);
  const std::set<ImagePair> s(pairs.begin(), pairs.end());
  // Along a line: footprints overlap up to 0.8 · 2 · 57.7 = 92 m, i.e. 3 frames ahead, never 4.
  for (uint32_t line = 0; line < 3; ++line)
    for (uint32_t k = 0; k < 8; ++k)
      for (uint32_t d = 1; k + d < 8; ++d) EXPECT_EQ(s.count({line * 8 + k, line * 8 + k + d}), d <= 3 ? 1u : 0u);
  // Across lines (200 m apart) nothing.
  for (const auto& [a, b] : pairs) EXPECT_EQ(a / 8, b / 8) << a << "-" << b;
  // The neighbour cap keeps the nearest ones.
  const auto capped = SpatialPairs(fps, 0.8, 1);
  for (const auto& [a, b] : capped) EXPECT_EQ(b - a, 1u);
}

TEST(SpatialPairs, FramesWithoutTelemetryGetSequentialNeighboursAndNoneFallsBack) {
  test::TempDir tmp;
  const auto index = GridFlight(tmp.path(), false);
  const auto fps = FootprintsFromTelemetry(index);
  EXPECT_FALSE(fps[0].valid);
  EXPECT_EQ(fps[0].why_invalid, "no telemetry");
  Descriptors empty(0, 128);
  std::vector<const Descriptors*> d(24, &empty);
  PairOptions po;
  po.mode = PairMode::kSpatial;
  po.overlap = 2;
  PairMode used = PairMode::kAuto;
  const auto pairs = SelectPairs(d, po, &used, nullptr, &fps);
  EXPECT_EQ(used, PairMode::kSpatial);
  const std::set<ImagePair> s(pairs.begin(), pairs.end());
  EXPECT_TRUE(s.count({0, 1}) && s.count({0, 2}));  // frame 0 has no footprint: sequential neighbours
  EXPECT_FALSE(s.count({0, 3}));
  EXPECT_TRUE(s.count({1, 4}));  // both have footprints 90 m apart: spatial
  // No telemetry at all: the mode kAuto would choose (24 images: exhaustive), not an error.
  std::vector<Footprint> none(24);
  const auto fallback = SelectPairs(d, po, &used, nullptr, &none);
  EXPECT_EQ(used, PairMode::kExhaustive);
  EXPECT_EQ(fallback.size(), 24u * 23 / 2);
}

TEST(SpatialPairs, ObliqueOrbitUsesTheFrameCentre) {
  // KLV-style: sensor 1000 m above ground on a 2 km orbit, frame centre at the orbit's centre.
  io::FramesIndex index;
  io::CameraPrior cam;
  cam.camera = core::Camera::Pinhole(360, 240, 432);
  index.cameras.push_back(cam);
  for (int k = 0; k < 12; ++k) {
    io::FrameRecord f;
    f.name = "orbit-" + std::to_string(k) + ".png";
    const double a = k * 30 * kDeg;
    f.telemetry = core::TelemetryFromJson({{"time", 0.0},
                                           {"sensor_latitude", LatOf(2000 * std::cos(a))},
                                           {"sensor_longitude", LonOf(2000 * std::sin(a))},
                                           {"sensor_altitude_msl", 1300.0},
                                           {"frame_center_latitude", LatOf(0)},
                                           {"frame_center_longitude", LonOf(0)},
                                           {"frame_center_elevation", 300.0},
                                           {"horizontal_fov", 2.0}});
    index.frames.push_back(f);
  }
  const auto fps = FootprintsFromTelemetry(index);
  for (const auto& f : fps) {
    ASSERT_TRUE(f.valid);
    EXPECT_LT((f.centre - fps[0].centre).norm(), 1.0);  // all at the orbit centre
    EXPECT_NEAR(f.centre.norm(), 2000, 5);              // which is 2 km from the first sensor position
  }
  // Every frame looks at the same spot: all pairs.
  EXPECT_EQ(SpatialPairs(fps, 0.8, 30).size(), 12u * 11 / 2);
}

}  // namespace
}  // namespace fmv3d::features
