// Georef's units alone, on synthetic inputs with exact answers: roll levelling from the ground, attitude fusion,
// the line-of-sight check, and the stage's verdict when the model's ground misses the telemetry's lines of sight.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/attitude_fusion.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/geo/line_of_sight_check.h"
#include "fmv3d/geo/roll_levelling.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "test_util.h"

namespace fmv3d::geo {
namespace {

constexpr double kDeg = M_PI / 180;
const GeoPoint kUnitsOrigin{38.16, -77.35, 60};

core::Sim3 TrueModelToEnu() {
  core::Sim3 s;
  s.s = 20;
  s.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.9, Eigen::Vector3d(0.2, 0.4, -0.9).normalized()));
  s.t = Eigen::Vector3d(5, -7, 30);
  return s;
}

// Rotates `s` about the ENU line through c along d by angle.
core::Sim3 TurnAbout(const core::Sim3& s, const Eigen::Vector3d& d, const Eigen::Vector3d& c, double angle) {
  const Eigen::Quaterniond r(Eigen::AngleAxisd(angle, d.normalized()));
  core::Sim3 out = s;
  out.q = r * s.q;
  out.t = r * (s.t - c) + c;
  return out;
}

double Distance(const core::Sim3& a, const core::Sim3& b) {
  return std::abs(a.s - b.s) + core::RotationAngle(a.q, b.q) + (a.t - b.t).norm();
}

TEST(RollLevelling, StraightTrackLevelledFromTheGroundExactly) {
  const core::Sim3 truth = TrueModelToEnu(), inv = truth.Inverse();
  std::vector<Eigen::Vector3d> src, dst, ground;
  for (int k = 0; k < 20; ++k) dst.emplace_back(-300 + 30.0 * k, -150, 120), src.push_back(inv.Apply(dst.back()));
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-200, 200);
  for (int i = 0; i < 300; ++i) ground.push_back(inv.Apply(Eigen::Vector3d{u(rng), u(rng), 0}));
  // 25% of the points on walls: the plane with the most points is still the ground.
  for (int i = 0; i < 100; ++i) ground.push_back(inv.Apply(Eigen::Vector3d{50, u(rng), 5 + std::abs(u(rng)) / 10}));
  const core::Sim3 rolled = TurnAbout(truth, Eigen::Vector3d::UnitX(), Eigen::Vector3d(0, -150, 120), 7 * kDeg);
  const RollLevelling r = LevelRollFromGround(rolled, src, dst, 0.01, ground);
  EXPECT_EQ(r.source, RollSource::kGroundPlane);
  EXPECT_LT(Distance(r.sim, truth), 1e-9);
  const auto normal = GroundNormal(ground, src.front());
  ASSERT_TRUE(normal);
  EXPECT_LT((truth.q * *normal - Eigen::Vector3d::UnitZ()).norm(), 1e-12);
  EXPECT_THROW(LevelRollFromGround(rolled, src, dst, 0.01, {ground.begin(), ground.begin() + 5}), Error);
}

TEST(RollLevelling, PositionsWithSidewaysSpreadKeepTheirRotation) {
  const core::Sim3 truth = TrueModelToEnu(), inv = truth.Inverse();
  std::vector<Eigen::Vector3d> src, dst;
  for (int k = 0; k < 12; ++k)
    dst.emplace_back(200 * std::cos(0.5 * k), 200 * std::sin(0.5 * k), 120), src.push_back(inv.Apply(dst.back()));
  const RollLevelling r = LevelRollFromGround(truth, src, dst, 3.0, {});
  EXPECT_EQ(r.source, RollSource::kCameraPositions);
  EXPECT_EQ(Distance(r.sim, truth), 0);
}

struct AttitudeCase {
  std::vector<GeorefPair> pairs;
  std::vector<Eigen::Vector3d> src, dst;
  std::vector<char> inliers;
};

// An orbit of cameras looking at the origin; the telemetry attitudes are exact.
AttitudeCase MakeAttitudeCase(const core::Sim3& truth) {
  AttitudeCase c;
  const core::Sim3 inv = truth.Inverse();
  for (int k = 0; k < 16; ++k) {
    const Eigen::Vector3d centre(200 * std::cos(0.4 * k), 200 * std::sin(0.4 * k), 120);
    const core::Pose enu_pose = core::Pose::LookAt(centre, Eigen::Vector3d::Zero());
    GeorefPair p;
    p.centre = inv.Apply(centre);
    // Model world-to-camera: ENU world-to-camera composed with model-to-ENU.
    p.rotation = (enu_pose.q * truth.q).normalized();
    p.attitude = enu_pose.R().transpose();  // camera-to-ENU
    c.pairs.push_back(p);
    c.src.push_back(p.centre);
    c.dst.push_back(centre);
  }
  c.inliers.assign(c.pairs.size(), 1);
  return c;
}

TEST(AttitudeFusion, AgreeingAttitudesFixTheRotation) {
  const core::Sim3 truth = TrueModelToEnu();
  const AttitudeCase c = MakeAttitudeCase(truth);
  // The positions' rotation 0.1° off; their σ (3 m over a 200 m orbit) allows it.
  const core::Sim3 off = TurnAbout(truth, Eigen::Vector3d(1, 1, 0), Eigen::Vector3d::Zero(), 0.1 * kDeg);
  const AttitudeFusion f = FuseAttitude(off, c.pairs, c.src, c.dst, c.inliers, 3.0);
  ASSERT_TRUE(f.evaluated);
  EXPECT_TRUE(f.used);
  EXPECT_EQ(f.frames, 16u);
  EXPECT_NEAR(f.sigma_rad, 1e-4, 1e-12);  // exact attitudes: the scatter's floor
  EXPECT_NEAR(f.disagreement_rad, 0.1 * kDeg, 1e-9);
  // Information-weighted: nearly all the way to the attitudes (σ 1e-4 rad against the positions' ~0.4°).
  EXPECT_LT(core::RotationAngle(f.sim.q, truth.q), 1e-3 * kDeg);
  EXPECT_NEAR(f.sim.s, truth.s, 1e-3 * truth.s);
  EXPECT_NEAR(f.correction_rad, 0.1 * kDeg, 1e-3 * kDeg);
  EXPECT_EQ(f.rotations.size(), 16u);
  EXPECT_EQ(f.ToJson()["used"], true);
}

TEST(AttitudeFusion, DisagreeingAttitudesAreNotUsed) {
  const core::Sim3 truth = TrueModelToEnu();
  const AttitudeCase c = MakeAttitudeCase(truth);
  // 5° off against positions of σ 0.01 m: far outside both uncertainties.
  const core::Sim3 off = TurnAbout(truth, Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero(), 5 * kDeg);
  const AttitudeFusion f = FuseAttitude(off, c.pairs, c.src, c.dst, c.inliers, 0.01);
  EXPECT_TRUE(f.evaluated);
  EXPECT_FALSE(f.used);
  EXPECT_GT(f.chi2, 16.3);
  EXPECT_EQ(Distance(f.sim, off), 0);
  EXPECT_TRUE(f.rotations.empty());
  EXPECT_NEAR(f.ToJson()["disagreement_deg"].get<double>(), 5, 1e-9);
  // Fewer than 3 attitudes: nothing to fuse.
  std::vector<GeorefPair> few = c.pairs;
  for (size_t i = 2; i < few.size(); ++i) few[i].attitude.reset();
  EXPECT_FALSE(FuseAttitude(off, few, c.src, c.dst, c.inliers, 0.01).evaluated);
}

// An ENU model: cameras along a straight track at 120 m looking at `look_at(k)` on level ground (z = 0), ground
// points seen by each; the telemetry states the sensor position and the frame centre `stated(k)`.
struct SightCase {
  core::Reconstruction model;
  std::vector<GeorefPair> keyframes;
  io::FramesIndex index;
};

template <typename LookAt, typename Stated>
SightCase MakeSightCase(const LocalFrame& frame, LookAt look_at, Stated stated) {
  SightCase c;
  c.model.cameras[1] = core::Camera::Pinhole(640, 360, 500);
  c.model.cameras[1].id = 1;
  c.model.cameras[1].u0 = 320, c.model.cameras[1].v0 = 180;
  c.index.cameras.push_back({c.model.cameras[1], fmv3d::io::ParsePriorSource("guess"), "flight.ts"});
  uint64_t next_point = 1;
  for (int gx = -40; gx <= 40; ++gx)
    for (int gy = -10; gy <= 40; ++gy) {
      core::Point3D p;
      p.id = next_point++;
      p.xyz = Eigen::Vector3d(15.0 * gx, 15.0 * gy, 0);
      c.model.points[p.id] = p;
    }
  for (int k = 0; k < 10; ++k) {
    const Eigen::Vector3d centre(-300 + 60.0 * k, -150, 120);
    core::Image img;
    img.id = k + 1;
    img.camera_id = 1;
    img.name = "flight-" + std::to_string(k) + ".png";
    img.pose = core::Pose::LookAt(centre, look_at(centre));
    for (auto& [id, p] : c.model.points) {
      const Eigen::Vector3d x = img.pose.Transform(p.xyz);
      if (x.z() <= 0) continue;
      const Eigen::Vector2d uv = c.model.cameras[1].Project(x);
      if (!c.model.cameras[1].InImage(uv)) continue;
      p.track.push_back({img.id, static_cast<uint32_t>(img.points2d.size())});
      img.points2d.push_back(uv);
      img.point3d_ids.push_back(static_cast<int64_t>(id));
    }
    c.model.images[img.id] = img;
    GeorefPair pair;
    pair.name = img.name;
    pair.centre = centre;
    pair.rotation = img.pose.q;
    // GPS noise of about half a metre (deterministic).
    pair.pos =
        frame.ToGeodetic(centre + 0.5 * Eigen::Vector3d(std::sin(1.7 * k), std::cos(2.3 * k), std::sin(0.9 * k)));
    pair.hae = pair.msl = pair.pos.alt;
    const GeoPoint f = frame.ToGeodetic(stated(centre));
    pair.frame_centre = GeoPoint{f.lat, f.lon, 0};
    pair.frame_centre_msl = pair.frame_centre_hae = f.alt;
    pair.slant_range = (stated(centre) - centre).norm();
    c.keyframes.push_back(pair);
    io::FrameRecord r;
    r.name = img.name;
    r.frame_index = k;
    r.timestamp = 0.5 * k;
    r.telemetry = core::TelemetryFromJson({{"time", r.timestamp},
                                           {"source", "ST0601"},
                                           {"sensor_latitude", pair.pos.lat},
                                           {"sensor_longitude", pair.pos.lon},
                                           {"sensor_altitude_hae", pair.pos.alt},
                                           {"sensor_altitude_msl", pair.pos.alt},
                                           {"frame_center_latitude", f.lat},
                                           {"frame_center_longitude", f.lon},
                                           {"frame_center_elevation", f.alt},
                                           {"slant_range", *pair.slant_range}});
    c.index.frames.push_back(r);
  }
  return c;
}

Eigen::Vector3d Ahead(const Eigen::Vector3d& c) { return {c.x(), 0, 0}; }
// 700 m beyond the true footprint and 30 m below it: the model's ground where the telemetry's is not.
Eigen::Vector3d Beyond(const Eigen::Vector3d& c) { return {c.x(), 120, -30}; }

TEST(LineOfSightCheck, AgreesWhereTheModelSeesTheTelemetrysFootprint) {
  const LocalFrame frame(kUnitsOrigin);
  const SightCase c = MakeSightCase(frame, Ahead, Ahead);
  const LineOfSightCheck r = CheckLinesOfSight(c.model, c.keyframes, VerticalDatum::kEllipsoid, frame, nullptr, {});
  EXPECT_EQ(r.verdict, LineOfSightCheck::Verdict::kAgrees) << r.Why();
  EXPECT_EQ(r.keyframes.size(), 10u);
  EXPECT_LT(r.median_angle_deg, 0.5);  // the median of the points near the image centre, on a 15 m grid
  EXPECT_LT(std::abs(r.median_along_m), 8.0);
  EXPECT_NEAR(r.median_sigma_deg, 1.0, 1e-12);  // no stated accuracy: the pointing σ alone
}

TEST(LineOfSightCheck, DisagreesAndSaysWhereWhenTheGroundIsBeyond) {
  const LocalFrame frame(kUnitsOrigin);
  // The model looks 120 m beyond the stated frame centre (and the frame centre is stated 30 m higher).
  const SightCase c = MakeSightCase(frame, Ahead, Beyond);
  GeorefAccuracy acc;
  acc.position_cov = Eigen::Matrix3d::Identity() * 4;  // 2 m per axis: does not excuse tens of degrees
  const LineOfSightCheck r = CheckLinesOfSight(c.model, c.keyframes, VerticalDatum::kEllipsoid, frame, &acc, {});
  EXPECT_EQ(r.verdict, LineOfSightCheck::Verdict::kDisagrees);
  EXPECT_GT(r.median_chi, 8);  // 9.6° off at σ ≈ 1°
  // The telemetry's ray S → (x, 120, −30) meets the model ground's height 0 at y = 66: the ground is short of it.
  EXPECT_NEAR(r.median_along_m, -66, 8);
  EXPECT_NE(r.Why().find("short of"), std::string::npos) << r.Why();
  EXPECT_EQ(r.ToJson()["verdict"], "disagrees");
  // Without stated heights the slant range places the frame centre: the same verdict.
  std::vector<GeorefPair> ranged = c.keyframes;
  for (auto& p : ranged) p.frame_centre_hae.reset(), p.frame_centre_msl.reset();
  const LineOfSightCheck from_range = CheckLinesOfSight(c.model, ranged, VerticalDatum::kEllipsoid, frame, &acc, {});
  EXPECT_EQ(from_range.verdict, LineOfSightCheck::Verdict::kDisagrees);
  EXPECT_NEAR(from_range.median_frame_centre_height_m, r.median_frame_centre_height_m, 1.0);  // GPS noise 0.5 m
  // Nothing to compare: neither a height nor a slant range.
  std::vector<GeorefPair> none = ranged;
  for (auto& p : none) p.slant_range.reset();
  EXPECT_EQ(CheckLinesOfSight(c.model, none, VerticalDatum::kEllipsoid, frame, &acc, {}).verdict,
            LineOfSightCheck::Verdict::kNotChecked);
  LineOfSightOptions bad;
  bad.pointing_sigma_deg = 0;
  EXPECT_THROW(CheckLinesOfSight(c.model, c.keyframes, VerticalDatum::kEllipsoid, frame, &acc, bad), Error);
}

// The model's ground on the telemetry's rays but 40 m below the frame centres (beyond them along the rays): the
// angle agrees, the height does not.
TEST(LineOfSightCheck, DisagreesWhenTheGroundIsBelowTheFrameCentres) {
  const LocalFrame frame(kUnitsOrigin);
  const auto above = [](const Eigen::Vector3d& c) {  // on the ray c → (x, 0, 0), 40 m above the ground
    const Eigen::Vector3d g(c.x(), 0, 0);
    return Eigen::Vector3d(c + (g - c) * (1 - 40 / c.z()));
  };
  const SightCase c = MakeSightCase(frame, Ahead, above);
  const LineOfSightCheck r = CheckLinesOfSight(c.model, c.keyframes, VerticalDatum::kEllipsoid, frame, nullptr, {});
  EXPECT_EQ(r.verdict, LineOfSightCheck::Verdict::kDisagrees);
  EXPECT_LT(r.median_chi, 1.0);  // the directions agree
  EXPECT_NEAR(r.median_below_m, 40, 3);
  EXPECT_NEAR(r.median_beyond_m, 40 / std::sin(std::atan2(120, 150)), 5);  // 64 m further along the ray
  EXPECT_NE(r.Why().find("below the telemetry's frame centres"), std::string::npos) << r.Why();
}

// The stage: a model whose ground lies beyond the telemetry's frame centres is written, georeferenced, but marked
// as not trusted, with the reason; the same model with agreeing frame centres is trusted.
TEST(LineOfSightCheck, StageMarksAModelOffTheLinesOfSightAsNotTrusted) {
  for (const bool off : {false, true}) {
    test::TempDir dir("georef-los");
    const LocalFrame frame(kUnitsOrigin);
    const SightCase c = off ? MakeSightCase(frame, Beyond, Ahead) : MakeSightCase(frame, Ahead, Ahead);
    core::EnsureDirectory(dir / "frames");
    io::WriteFramesIndex(c.index, dir / "frames/frames.json");
    const core::Sim3 model_from_enu = TrueModelToEnu().Inverse();
    core::Reconstruction model = c.model;
    model.Transform(model_from_enu);
    io::WriteColmapText(model, dir / "sparse");
    GeorefOptions o;
    o.origin = kUnitsOrigin;
    o.constrain = GeorefOptions::Constrain::kNever;
    o.use_frame_centres = false;  // the check alone decides
    const auto j = RunGeorefStage(dir.path(), o);
    EXPECT_EQ(j["trusted"].get<bool>(), !off) << j["line_of_sight"].dump();
    EXPECT_EQ(j["line_of_sight"]["verdict"], off ? "disagrees" : "agrees");
    EXPECT_EQ(ReadGeoref(dir.path()).trusted, !off);
    if (off) {
      EXPECT_NE(j["untrusted_reason"].get<std::string>().find("lines of sight"), std::string::npos);
      EXPECT_NEAR(j["line_of_sight"]["median_along_m"].get<double>(), 66, 8);  // beyond the telemetry's footprint
    }
  }
}

}  // namespace
}  // namespace fmv3d::geo
