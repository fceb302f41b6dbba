// geo/trajectory: interpolation of the registered cameras in time, and georef's use of every telemetry packet
// (frames/telemetry.json) against it.
#include "fmv3d/geo/trajectory.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/telemetry.h"
#include "random_draw.h"
#include "test_util.h"

namespace fmv3d::geo {
namespace {

Eigen::Vector3d Orbit(double t) {  // 80 m radius, one turn in 20 s, gently climbing
  const double a = 2 * M_PI * t / 20;
  return {80 * std::cos(a), 80 * std::sin(a), 100 + 0.5 * t};
}

TEST(Trajectory, CubicInTimeAndSlerpInRotation) {
  std::vector<TrajectoryKnot> knots;
  for (int k = 0; k <= 24; ++k) {  // every 0.8 s (14.4° of orbit), given out of order
    const double t = (k * 7 % 25) * 0.8;
    knots.push_back({t, Orbit(t), Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * t, Eigen::Vector3d::UnitZ()))});
  }
  const CameraTrajectory traj(knots);
  EXPECT_NEAR(traj.max_gap(), 2.0, 1e-9);  // 2.5 × 0.8 s
  double worst = 0;
  for (double t = 0; t <= 19.2; t += 0.0333) {
    const auto k = traj.At(t);
    ASSERT_TRUE(k) << t;
    worst = std::max(worst, (k->centre - Orbit(t)).norm());
    const double angle =
        k->rotation.angularDistance(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * t, Eigen::Vector3d::UnitZ())));
    EXPECT_LT(angle, 1e-9);
  }
  EXPECT_LT(worst, 0.05);  // a linear interpolation would be off by ~R(1 − cos 7.2°) = 0.63 m
  EXPECT_FALSE(traj.At(-0.01));
  EXPECT_FALSE(traj.At(19.21));
}

TrajectoryKnot Knot(double t) { return {t, Orbit(t), Eigen::Quaterniond::Identity()}; }

TEST(Trajectory, NeverBridgesAGap) {
  std::vector<TrajectoryKnot> knots;
  for (double t : {0.0, 1.0, 2.0, 3.0, 9.0, 10.0, 11.0}) knots.push_back(Knot(t));
  const CameraTrajectory traj(knots);
  EXPECT_TRUE(traj.At(2.5));
  EXPECT_FALSE(traj.At(5.0));
  const auto k = traj.At(9.5);  // the stencil stays on its side of the gap
  ASSERT_TRUE(k);
  EXPECT_LT((k->centre - Orbit(9.5)).norm(), 0.2);
  EXPECT_THROW(CameraTrajectory({Knot(1), Knot(1)}), Error);
}

TEST(TelemetryTrack, RoundTripsThroughJson) {
  test::TempDir dir("track");
  telemetry::TelemetryTrack track{"flight.ts", {}};
  telemetry::TelemetrySample s;
  s.time = 0.5;
  s.source = "ST0601";
  s.sensor_latitude = 38.16;
  s.sensor_longitude = -77.35;
  s.sensor_altitude_hae = 140.25;
  s.platform_heading = 271;
  s.unix_time_us = 1717243200500000ull;
  track.samples.push_back(s);
  telemetry::WriteTelemetryTracks({track}, dir / "telemetry.json");
  const auto back = telemetry::ReadTelemetryTracks(dir / "telemetry.json");
  ASSERT_EQ(back.size(), 1u);
  ASSERT_EQ(back[0].samples.size(), 1u);
  const auto& b = back[0].samples[0];
  EXPECT_EQ(back[0].source, "flight.ts");
  EXPECT_EQ(b.time, 0.5);
  EXPECT_EQ(*b.sensor_latitude, 38.16);
  EXPECT_EQ(*b.sensor_altitude_hae, 140.25);
  EXPECT_EQ(*b.platform_heading, 271);
  EXPECT_FALSE(b.sensor_altitude_msl);
  EXPECT_EQ(*b.unix_time_us, 1717243200500000ull);
  core::WriteJson(dir / "bad.json", {{"tracks", {{{"source", "x"}, {"samples", {{{"sensor_latitude", 1}}}}}}}});
  EXPECT_THROW(telemetry::ReadTelemetryTracks(dir / "bad.json"), Error);
}

// A 30 fps video of 600 packets with GPS noise σ = 3 m, of which only every 12th frame is a registered keyframe:
// fitting every packet against the model trajectory fixes the frame ~√12 times better than the keyframes alone
// (in expectation; this draw's keyframe translation happens to be good, its scale is not).
TEST(Georef, EveryTelemetryPacketAgainstTheTrajectory) {
  test::TempDir dir("georef-track");
  const GeoPoint origin{38.16, -77.35, 60};
  const LocalFrame frame(origin);
  core::Sim3 true_to_model;
  true_to_model.s = 0.05;
  true_to_model.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()));
  true_to_model.t = Eigen::Vector3d(1, -2, 3);
  core::Reconstruction rec;
  rec.cameras[1] = core::Camera::Pinhole(640, 360, 500);
  rec.cameras[1].id = 1;
  io::FramesIndex index;
  index.cameras.push_back({rec.cameras[1], fmv3d::io::ParsePriorSource("guess"), "flight.ts"});
  telemetry::TelemetryTrack track{"flight.ts", {}};
  std::mt19937_64 rng(11);
  std::normal_distribution<double> N(0, 1);
  auto sample = [&](double t) {
    const GeoPoint p = frame.ToGeodetic(Orbit(t) + 3.0 * test::DrawLastFirst<3>(N, rng));
    telemetry::TelemetrySample s;
    s.time = t;
    s.source = "ST0601";
    s.sensor_latitude = p.lat, s.sensor_longitude = p.lon, s.sensor_altitude_hae = p.alt;
    return s;
  };
  for (int k = 0; k < 600; ++k) {
    const double t = k / 30.0;
    track.samples.push_back(sample(t));
    if (k % 12) continue;
    core::Image img;
    img.id = static_cast<uint32_t>(rec.images.size() + 1);
    img.camera_id = 1;
    img.name = fmt::format("flight-{:06d}.png", k);
    img.pose = true_to_model.Apply(core::Pose::LookAt(Orbit(t), {0, 0, 0}));
    rec.images[img.id] = img;
    io::FrameRecord f;
    f.name = img.name;
    f.source = "flight.ts";
    f.frame_index = k;
    f.timestamp = t;
    f.telemetry = track.samples.back();
    index.frames.push_back(f);
  }
  core::EnsureDirectory(dir / "frames");
  io::WriteFramesIndex(index, dir / "frames/frames.json");
  io::WriteColmapText(rec, dir / "sparse");
  auto bias = [&] {  // mean camera error = the georeference's translation error (a rigid model)
    const core::Reconstruction enu = io::ReadColmapText(dir / "geo/sparse_enu");
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const auto& [id, img] : enu.images) sum += img.pose.Centre() - Orbit((id - 1) * 12 / 30.0);
    return (sum / static_cast<double>(enu.images.size())).norm();
  };
  GeorefOptions o;
  o.origin = origin;
  const auto kf = RunGeorefStage(dir.path(), o);  // no telemetry.json yet: keyframes only
  EXPECT_EQ(kf["fit"]["from"], "keyframes");
  EXPECT_EQ(kf["fit"]["pairs"].get<int>(), 50);
  const double kf_bias = bias();
  telemetry::WriteTelemetryTracks({track}, dir / "frames/telemetry.json");
  const auto tr = RunGeorefStage(dir.path(), o);
  EXPECT_TRUE(tr["fit"]["used"].get<bool>());
  EXPECT_EQ(tr["fit"]["pairs"].get<int>(), 589);  // packets inside the registered span (0 .. 19.6 s)
  EXPECT_NEAR(tr["fit"]["effective_samples"].get<double>(), 589, 60);  // white noise: ρ ≈ 0
  EXPECT_NEAR(tr["residuals"]["sigma_per_axis_m"].get<double>(), 3.0, 0.3);
  EXPECT_NEAR(tr["expected_translation_error_m"].get<double>(), 3 * std::sqrt(3.0 / 589), 0.05);
  const double tr_bias = bias();
  std::cout << "translation error: keyframes " << kf_bias << " m, every packet " << tr_bias << " m\n";
  EXPECT_LT(tr_bias, 0.45);  // 3σ of the 3D mean of 589 draws
  EXPECT_LT(tr_bias, kf_bias);
  // Scale (true 1 / 0.05 = 20): known to ~σ/(R·√N) — 0.07% with every packet, 0.25% with the keyframes.
  EXPECT_NEAR(tr["similarity"]["scale"].get<double>(), 20, 20 * 0.002);
  EXPECT_LT(std::abs(tr["similarity"]["scale"].get<double>() - 20),
            std::abs(kf["similarity"]["scale"].get<double>() - 20));
  o.use_track = false;
  EXPECT_EQ(RunGeorefStage(dir.path(), o)["fit"]["from"], "keyframes");
}

}  // namespace
}  // namespace fmv3d::geo
