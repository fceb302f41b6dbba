// One file (~900 lines) on purpose: the georef cases share one synthetic-model builder (GeorefCase) and the DSM
// cases the GDAL read-back helpers; split, the parts would each compile the Open3D and GDAL headers again in CI.
// geo/: PROJ frames against the independent closed-form geodesy of synth/, the robust georeference on
// synthetic models with known similarities (noise, an outlier, a straight track), DSM / orthophoto rasters on
// a known mesh, GeoTIFF and LAS read back.
#include <gdal_priv.h>
#include <gdal_utils.h>
#include <gtest/gtest.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>
#include <proj.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/dsm.h"
#include "fmv3d/geo/frame_centres.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/geo/las.h"
#include "fmv3d/geo/raster.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/synth/telemetry.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/klv_st0601_writer.h"
#include "random_draw.h"
#include "test_util.h"

namespace fmv3d::geo {
namespace {

// What `gdalinfo FILE` prints (GDAL's own library entry point for it).
std::string GdalInfo(const std::filesystem::path& path) {
  GDALAllRegister();
  GDALDatasetH ds = GDALOpen(path.c_str(), GA_ReadOnly);
  if (!ds) return "";
  char* text = GDALInfo(ds, nullptr);
  std::string out = text ? text : "";
  CPLFree(text);
  GDALClose(ds);
  return out;
}

// Pixel (band b, row r, col c) of a GeoTIFF.
int Pixel(const std::filesystem::path& path, int band, int r, int c) {
  GDALAllRegister();
  GDALDataset* ds = static_cast<GDALDataset*>(GDALOpen(path.c_str(), GA_ReadOnly));
  if (!ds) return -1;
  uint8_t v = 0;
  const CPLErr err = ds->GetRasterBand(band)->RasterIO(GF_Read, c, r, 1, 1, &v, 1, 1, GDT_Byte, 0, 0);
  GDALClose(ds);
  return err == CE_None ? v : -1;
}

namespace fs = std::filesystem;
const GeoPoint kOrigin{38.16, -77.35, 60};

// LocalFrame's own ENU ↔ WGS84 against PROJ's cart + topocentric pipeline (EnuPipeline()) and synth's.
TEST(Geodesy, EnuAgreesWithProjPipeline) {
  const LocalFrame frame(kOrigin);
  PJ_CONTEXT* ctx = proj_context_create();
  PJ* enu = proj_create(ctx, frame.EnuPipeline().c_str());
  ASSERT_NE(enu, nullptr);
  const synth::GeoPoint so{kOrigin.lat, kOrigin.lon, kOrigin.alt};
  for (const Eigen::Vector3d& e : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(120, -340, 95),
                                   Eigen::Vector3d(-3000, 2500, 800), Eigen::Vector3d(40000, -25000, -900)}) {
    const PJ_COORD g = proj_trans(enu, PJ_INV, proj_coord(e.x(), e.y(), e.z(), 0));
    const GeoPoint p = frame.ToGeodetic(e);
    EXPECT_NEAR(p.lat, g.xyz.y, 1e-10) << e.transpose();
    EXPECT_NEAR(p.lon, g.xyz.x, 1e-10) << e.transpose();
    EXPECT_NEAR(p.alt, g.xyz.z, 1e-6) << e.transpose();
    EXPECT_LT((frame.ToEnu(p) - e).norm(), 1e-6) << e.transpose();
    const auto s = synth::EnuToGeodetic(e, so);
    EXPECT_NEAR(p.lat, s.lat, 1e-12);
    EXPECT_NEAR(p.alt, s.alt, 1e-8);
  }
  proj_destroy(enu);
  proj_context_destroy(ctx);
  EXPECT_THROW(frame.ToGeodetic(Eigen::Vector3d(NAN, 0, 0)), Error);
}

// EGM96 from PROJ's grid (proj-data, a dependency of libproj): known values at (0, 0) and at synth's origin.
TEST(Geodesy, GeoidUndulationFromEgm96) {
  const auto equator = GeoidUndulation(0, 0), virginia = GeoidUndulation(38.16, -77.35);
  ASSERT_TRUE(equator && virginia) << "egm96_15.gtx missing (Debian proj-data)";
  EXPECT_NEAR(*equator, 17.16, 0.05);
  EXPECT_NEAR(*virginia, -33.87, 0.05);
}

TEST(Geodesy, UtmZoneAndCentralMeridian) {
  EXPECT_EQ(UtmZoneOf(38.16, -77.35).zone, 18);
  EXPECT_EQ(UtmZoneOf(38.16, -77.35).Epsg(), 32618);
  EXPECT_EQ(UtmZoneOf(-33.9, 18.4).Epsg(), 32734);
  EXPECT_EQ(UtmZoneOf(60, 5).zone, 32);  // Norway exception
  EXPECT_THROW(UtmZoneOf(89, 0), Error);
  const LocalFrame frame(kOrigin);
  // On the zone's central meridian (75° W) the easting is the false easting, 500 km; at the equator N = 0.
  const Eigen::Vector3d e = frame.GeodeticToUtm({0, -75, 10});
  EXPECT_NEAR(e.x(), 500000, 1e-6);
  EXPECT_NEAR(e.y(), 0, 1e-6);
  EXPECT_NEAR(e.z(), 10, 1e-9);
  // Round trip, and the UTM scale (~0.9996 near the central meridian, more 2.35° off it) over 1 km east.
  const Eigen::Vector3d a = frame.EnuToUtm({0, 0, 0}), b = frame.EnuToUtm({1000, 0, 0});
  EXPECT_NEAR((b - a).head<2>().norm(), 1000, 1.0);
  const GeoPoint back = frame.UtmToGeodetic(a);
  EXPECT_NEAR(back.lat, kOrigin.lat, 1e-9);
  EXPECT_NEAR(back.lon, kOrigin.lon, 1e-9);
  std::vector<Eigen::Vector3d> batch = {{0, 0, 0}, {1000, 0, 0}};
  frame.EnuToUtm(&batch);
  EXPECT_LT((batch[0] - a).norm(), 1e-6);
  EXPECT_LT((batch[1] - b).norm(), 1e-6);
  EXPECT_NE(UtmWkt(frame.utm_zone()).find("UTM zone 18N"), std::string::npos);
}

// A workspace with a model that is the truth under a known similarity, and telemetry = noisy truth.
struct GeorefCase {
  test::TempDir dir{"georef"};
  std::vector<Eigen::Vector3d> true_centres;  // ENU
  core::Sim3 true_to_model;
};

// attitude_noise < 0: no attitude in the telemetry; heading_offset: a systematic heading error (degrees).
// frame_centre_noise < 0: no frame centres; else each packet states the true look-at point (plus that noise per
// axis and frame_centre_offset) with its slant range. ground_tilt_deg tilts the model's ground about the x axis.
// The point camera k looks at (its frame centre): the origin, or spread about it as a jittery gimbal's.
Eigen::Vector3d CaseLookAt(int k, double spread) {
  return spread * Eigen::Vector3d(std::cos(2.7 * k), std::sin(2.7 * k), 0);
}

void MakeGeorefCase(GeorefCase* g, int n, double noise, bool straight, int outlier, double attitude_noise = -1,
                    double heading_offset = 0, double radius = 200, double bend = 0, double frame_centre_noise = -1,
                    const Eigen::Vector3d& frame_centre_offset = Eigen::Vector3d::Zero(), double ground_tilt_deg = 0,
                    double look_at_spread = 0) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0, 1);
  std::mt19937_64 rng_att(9);  // separate, so positions are the same with and without attitude
  std::normal_distribution<double> Na(0, 1);
  core::Reconstruction rec;
  rec.cameras[1] = core::Camera::Pinhole(640, 360, 500);
  rec.cameras[1].id = 1;
  g->true_to_model.s = 0.05;
  g->true_to_model.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()));
  g->true_to_model.t = Eigen::Vector3d(1, -2, 3);
  io::FramesIndex index;
  index.cameras.push_back({rec.cameras[1], fmv3d::io::ParsePriorSource("guess"), "flight.ts"});
  const LocalFrame frame(kOrigin);
  for (int k = 0; k < n; ++k) {
    Eigen::Vector3d c;
    if (straight)
      c = Eigen::Vector3d(-300 + 600.0 * k / (n - 1), -150, 120);
    else
      c = Eigen::Vector3d(radius * std::cos(2 * M_PI * k / n), radius * std::sin(2 * M_PI * k / n),
                          120 + 10 * std::sin(3.0 * k));
    g->true_centres.push_back(c);
    const Eigen::Vector3d look_at = CaseLookAt(k, look_at_spread);
    core::Image img;
    img.id = k + 1;
    img.camera_id = 1;
    img.name = fmt::format("flight-{:06d}.png", k);
    img.pose = g->true_to_model.Apply(core::Pose::LookAt(c, look_at));
    rec.images[img.id] = img;
    io::FrameRecord f;
    f.name = img.name;
    f.frame_index = k;
    Eigen::Vector3d noisy = c + noise * test::DrawLastFirst<3>(N, rng);
    if (k == outlier) noisy += Eigen::Vector3d(150, -80, 40);
    if (10 * k >= 7 * n) noisy += Eigen::Vector3d(bend, 0, 0);  // the model's last 30% is not where the flight was
    const GeoPoint p = frame.ToGeodetic(noisy);
    f.telemetry = core::TelemetryFromJson({{"time", k * 0.1},
                                           {"source", "ST0601"},
                                           {"sensor_latitude", p.lat},
                                           {"sensor_longitude", p.lon},
                                           {"sensor_altitude_hae", p.alt},
                                           {"sensor_altitude_msl", p.alt}});
    if (attitude_noise >= 0) {
      // Split the true attitude for a nominal platform, then state a noisy (and offset) platform, as synth does:
      // the telemetry's camera attitude is off by about attitude_noise per axis (and by heading_offset).
      const Eigen::Matrix3d cam_to_enu = core::Pose::LookAt(c, look_at).R().transpose();
      const auto a = telemetry::St0601FromCameraToEnu(cam_to_enu, 90, 0, 0);
      f.telemetry->platform_heading = 90 + heading_offset + attitude_noise * Na(rng_att);
      f.telemetry->platform_pitch = attitude_noise * Na(rng_att);
      f.telemetry->platform_roll = attitude_noise * Na(rng_att);
      f.telemetry->sensor_relative_azimuth = a.sensor_relative_azimuth;
      f.telemetry->sensor_relative_elevation = a.sensor_relative_elevation;
      f.telemetry->sensor_relative_roll = a.sensor_relative_roll;
    }
    if (frame_centre_noise >= 0) {
      std::normal_distribution<double> Nf(0, frame_centre_noise);
      const Eigen::Vector3d fc = look_at + test::DrawLastFirst<3>(Nf, rng_att) + frame_centre_offset;
      const GeoPoint q = frame.ToGeodetic(fc);
      f.telemetry->frame_center_latitude = q.lat;
      f.telemetry->frame_center_longitude = q.lon;
      f.telemetry->frame_center_elevation = q.alt;
      f.telemetry->slant_range = (c - look_at).norm();  // to the true look-at point
    }
    index.frames.push_back(f);
  }
  // Ground points (a plane with small bumps) so the model has a ground.
  for (int i = 0; i < 400; ++i) {
    core::Point3D pt;
    pt.id = i + 1;
    const int row = i / 20;
    const double y = -200 + 20.0 * row;
    pt.xyz = g->true_to_model.Apply(
        Eigen::Vector3d(-200 + 20.0 * (i % 20), y, 0.5 * N(rng) + y * std::tan(ground_tilt_deg * M_PI / 180)));
    rec.points[pt.id] = pt;
  }
  core::EnsureDirectory(g->dir / "frames");
  io::WriteFramesIndex(index, g->dir / "frames/frames.json");
  io::WriteColmapText(rec, g->dir / "sparse");
}

double CentreRms(const GeorefCase& g) {
  const core::Reconstruction enu = io::ReadColmapText(g.dir / "geo/sparse_enu");
  double sq = 0;
  for (const auto& [id, img] : enu.images) sq += (img.pose.Centre() - g.true_centres[id - 1]).squaredNorm();
  return std::sqrt(sq / enu.images.size());
}

TEST(Georef, ExactTelemetryRecoversTheSimilarity) {
  GeorefCase g;
  MakeGeorefCase(&g, 20, 0.0, false, -1);
  GeorefOptions o;
  o.origin = kOrigin;
  const auto j = RunGeorefStage(g.dir.path(), o);
  EXPECT_LT(CentreRms(g), 1e-3);
  EXPECT_NEAR(j["similarity"]["scale"].get<double>(), 1 / g.true_to_model.s, 1e-6);
  EXPECT_EQ(j["utm"]["epsg"].get<int>(), 32618);
  const Georef back = ReadGeoref(g.dir.path());
  EXPECT_NEAR(back.sparse_to_enu.s, 1 / g.true_to_model.s, 1e-6);
  EXPECT_EQ(back.vertical_datum, "WGS84 ellipsoid");
}

TEST(Georef, NoisyTelemetryWithAnOutlier) {
  GeorefCase g;
  const int n = 80;
  MakeGeorefCase(&g, n, 3.0, false, 7);
  GeorefOptions o;
  o.origin = kOrigin;
  const auto j = RunGeorefStage(g.dir.path(), o);
  // The outlier is rejected, the rest kept; the frame is known to ~σ·√(3/N) ≈ 0.6 m (3D), cameras likewise.
  const auto& per = j["residuals"]["per_image"];
  EXPECT_FALSE(per[7]["inlier"].get<bool>());
  EXPECT_GE(j["inliers"].get<int>(), n - 3);
  EXPECT_NEAR(j["residuals"]["sigma_per_axis_m"].get<double>(), 3.0, 0.6);
  EXPECT_LT(CentreRms(g), 1.5);
  EXPECT_TRUE(j["consistent_with_telemetry"].get<bool>());
  EXPECT_TRUE(ReadGeoref(g.dir.path()).consistent_with_telemetry);
}

// A reconstruction whose trajectory does not have the flight's shape (here: its last 30% is 60 m off, as a
// telephoto model with a wrong relative pose is) cannot be georeferenced by a similarity: georef says so.
TEST(Georef, ModelThatDisagreesWithTheFlightIsFlagged) {
  GeorefCase g;
  MakeGeorefCase(&g, 40, 3.0, false, -1, -1, 0, 200, 60);
  GeorefOptions o;
  o.origin = kOrigin;
  const auto j = RunGeorefStage(g.dir.path(), o);
  EXPECT_FALSE(j["consistent_with_telemetry"].get<bool>()) << j["fit_fraction"];
  EXPECT_LT(j["fit_fraction"].get<double>(), 0.8);
  EXPECT_FALSE(ReadGeoref(g.dir.path()).consistent_with_telemetry);
}

// The same kind of model (the last 30% of its cameras 60 m off the flight), but this time with image
// observations (true projections of the ground points, 0.3 px noise) and ST 0601 attitudes (σ 0.5°) in the
// telemetry: georef builds the model again from the telemetry's cameras and the observations, keeps it because it
// fits the flight, and the cameras land within the telemetry's noise of the truth.
// Image observations for a case's model (true projections of its ground points, 0.3 px noise), then its last
// 30% of cameras moved 60 m: a bent model, as a telephoto pass's image model is.
void ObserveAndBend(GeorefCase* g, int n, double look_at_spread, double bend_m = 60) {
  core::Reconstruction rec = io::ReadColmapText(g->dir / "sparse");
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0, 0.3);
  const core::Sim3 model_to_true = g->true_to_model.Inverse();
  for (auto& [pid, pt] : rec.points) {
    const Eigen::Vector3d X = model_to_true.Apply(pt.xyz);
    for (auto& [id, img] : rec.images) {
      const core::Pose truth = core::Pose::LookAt(g->true_centres[id - 1], CaseLookAt(id - 1, look_at_spread));
      const Eigen::Vector3d xc = truth.Transform(X);
      if (xc.z() <= 0) continue;
      const Eigen::Vector2d uv = rec.cameras.at(1).Project(xc) + test::DrawLastFirst<2>(N, rng);
      if (!rec.cameras.at(1).InImage(uv, 2)) continue;
      pt.track.push_back({static_cast<uint32_t>(id), static_cast<uint32_t>(img.points2d.size())});
      img.points2d.push_back(uv);
      img.point3d_ids.push_back(static_cast<int64_t>(pid));
    }
  }
  for (auto& [id, img] : rec.images) {
    if (10 * (id - 1) < 7 * n) continue;
    const Eigen::Vector3d c =
        img.pose.Centre() + g->true_to_model.s * (g->true_to_model.q * Eigen::Vector3d(bend_m, 0, 0));
    img.pose.t = -(img.pose.q * c);
  }
  rec.Validate();
  io::WriteColmapText(rec, g->dir / "sparse");
}

TEST(Georef, ModelThatDisagreesIsBuiltAgainFromTheTelemetry) {
  GeorefCase g;
  const int n = 40;
  MakeGeorefCase(&g, n, 3.0, false, -1, 0.5, 0, 200, 0);
  ObserveAndBend(&g, n, 0);
  GeorefOptions o;
  o.origin = kOrigin;
  const auto j = RunGeorefStage(g.dir.path(), o);
  ASSERT_TRUE(j.contains("telemetry_constrained"));
  const auto& t = j["telemetry_constrained"];
  EXPECT_TRUE(t.value("applied", false)) << t.dump();
  EXPECT_LT(t.value("fit_fraction_image_only", 1.0), 0.8);
  EXPECT_TRUE(j["consistent_with_telemetry"].get<bool>()) << j["fit_fraction"];
  EXPECT_LT(t.value("reprojection_rms_px", 1e9), 1.0);
  // Measured 1.73 m (40 keyframes with σ 3 m per axis: ~1.2 m from the similarity alone; the priors bend the
  // shape a little). The bent image model's last 12 cameras were 60 m off.
  EXPECT_LT(CentreRms(g), 2.0);
  EXPECT_TRUE(fs::exists(g.dir / "geo/sparse_image_only/images.txt"));
  // WS/sparse now holds the rebuilt model, and georef.json's similarity maps it into ENU.
  EXPECT_EQ(io::ReadColmapText(g.dir / "sparse").images.size(), static_cast<size_t>(n));
}

// The same bent model, with precise frame centres (1 cm) spread 17 m about the look-at point: they enter the
// rebuilt model's bundle adjustment as priors on the point along each optical axis, weighed by their own scatter
// (estimated again after each adjustment), and the cameras land far closer than the GPS alone puts them.
TEST(Georef, FrameCentresArePriorsOfTheRebuiltModel) {
  double rms[2];
  for (int use = 0; use < 2; ++use) {
    GeorefCase g;
    const int n = 40;
    MakeGeorefCase(&g, n, 3.0, false, -1, 0.5, 0, 200, 0, 0.01, Eigen::Vector3d::Zero(), 0, 17);
    ObserveAndBend(&g, n, 17);
    GeorefOptions o;
    o.origin = kOrigin;
    o.use_frame_centres = use == 1;
    const auto j = RunGeorefStage(g.dir.path(), o);
    const auto& t = j["telemetry_constrained"];
    EXPECT_TRUE(t.value("applied", false)) << t.dump();
    EXPECT_EQ(t.value("frame_centre_priors", 0), use ? n : 0) << t.dump();
    rms[use] = CentreRms(g);
    if (use) {
      // The prior σ settled near the frame centres' own 1 cm (from metres under the GPS-placed model).
      EXPECT_LT(t["frame_centre_prior_sigma_m"].back().get<double>(), 0.05) << t.dump();
      EXPECT_TRUE(j["frame_centres"]["used"].get<bool>()) << j["frame_centres"].dump();
    }
  }
  std::cout << "rebuilt model's cameras: GPS priors only " << rms[0] << " m, with frame-centre priors " << rms[1]
            << " m\n";
  EXPECT_LT(rms[1], 0.5);
  EXPECT_LT(rms[1], 0.5 * rms[0]);
}

// The fusion weighs each source by its information: precise positions on a wide orbit are not pulled off by
// 1° attitudes; noisy positions on a tight orbit (rotation known to ~1.4°) are sharpened by 0.2° attitudes.
double RotationErrorDeg(const GeorefCase& g) {
  const Georef r = ReadGeoref(g.dir.path());
  return core::RotationAngle(r.sparse_to_enu.q * g.true_to_model.q, Eigen::Quaterniond::Identity()) * 180 / M_PI;
}

TEST(Georef, AttitudeFusionWeighsBothSources) {
  {
    GeorefCase g;
    MakeGeorefCase(&g, 40, 0.01, false, -1, 1.0);
    const auto j = RunGeorefStage(g.dir.path(), {});
    EXPECT_TRUE(j["attitude"]["used"].get<bool>()) << j["attitude"].dump();
    EXPECT_LT(RotationErrorDeg(g), 0.005);
  }
  double err[2];
  for (int use = 0; use < 2; ++use) {
    GeorefCase g;
    MakeGeorefCase(&g, 40, 3.0, false, -1, use ? 0.2 : -1, 0, 20);
    const auto j = RunGeorefStage(g.dir.path(), {});
    EXPECT_EQ(j["attitude"]["used"].get<bool>(), use == 1) << j["attitude"].dump();
    err[use] = RotationErrorDeg(g);
  }
  EXPECT_LT(err[1], 0.15) << "positions only: " << err[0];
}

TEST(Georef, InconsistentAttitudeIsNotUsed) {
  GeorefCase g;
  MakeGeorefCase(&g, 40, 1.0, false, -1, 0.2, 20.0);  // every attitude 20° off in heading
  const auto j = RunGeorefStage(g.dir.path(), {});
  EXPECT_FALSE(j["attitude"]["used"].get<bool>()) << j["attitude"].dump();
  EXPECT_NEAR(j["attitude"]["disagreement_deg"].get<double>(), 20, 1);
}

TEST(Georef, StraightTrackTakesItsRollFromTheGround) {
  GeorefCase g;
  MakeGeorefCase(&g, 30, 1.0, true, -1);
  const auto j = RunGeorefStage(g.dir.path(), {});  // origin: the telemetry centroid
  EXPECT_NE(j["rotation_about_track_from"].get<std::string>().find("ground"), std::string::npos);
  // Rotation error: the model's rotation composed with the recovered one should be the identity.
  const Georef r = ReadGeoref(g.dir.path());
  const double angle = core::RotationAngle(r.sparse_to_enu.q * g.true_to_model.q, Eigen::Quaterniond::Identity());
  EXPECT_LT(angle * 180 / M_PI, 1.0);
}

// Error of the georeferenced model at a true ENU point X (the model's X mapped back to ENU).
double ErrorAt(const GeorefCase& g, const Eigen::Vector3d& X) {
  return (ReadGeoref(g.dir.path()).sparse_to_enu.Apply(g.true_to_model.Apply(X)) - X).norm();
}

// 12 packets with σ = 3 m GPS know the translation to ~1.5 m; their frame centres (1 cm) at the slant range
// place every sensor along the model's own line of sight, and pin the ground the cameras look at.
TEST(Georef, FrameCentresPinTheTranslationAndScale) {
  double err[2];
  for (int use = 0; use < 2; ++use) {
    GeorefCase g;
    MakeGeorefCase(&g, 12, 3.0, false, -1, 0.5, 0, 200, 0, 0.01);
    GeorefOptions o;
    o.origin = kOrigin;
    o.use_frame_centres = use == 1;
    const auto j = RunGeorefStage(g.dir.path(), o);
    EXPECT_EQ(j["frame_centres"]["used"].get<bool>(), use == 1) << j["frame_centres"].dump();
    err[use] = ErrorAt(g, Eigen::Vector3d::Zero());
    if (use) {
      EXPECT_EQ(j["frame_centres"]["inliers"].get<int>(), 12);
      EXPECT_LT(j["frame_centres"]["sigma_per_axis_m"].get<double>(), 0.1);
    }
  }
  std::cout << "error at the look-at point: positions " << err[0] << " m, frame centres " << err[1] << " m\n";
  EXPECT_GT(err[0], 0.3);  // positions and attitudes only
  EXPECT_LT(err[1], 0.1) << "positions only: " << err[0];
}

// A datum mistake (every frame centre 30 m too low) must not drag the model: the frame centres' own fit
// disagrees with the positions', and they are left out.
TEST(Georef, FrameCentresThatDisagreeAreNotUsed) {
  GeorefCase g;
  MakeGeorefCase(&g, 40, 3.0, false, -1, 0.5, 0, 200, 0, 0.01, Eigen::Vector3d(0, 0, -30));
  GeorefOptions o;
  o.origin = kOrigin;
  const auto j = RunGeorefStage(g.dir.path(), o);
  EXPECT_FALSE(j["frame_centres"]["used"].get<bool>()) << j["frame_centres"].dump();
  EXPECT_NE(j["frame_centres"]["why"].get<std::string>().find("disagree"), std::string::npos);
  EXPECT_LT(CentreRms(g), 3.0);  // the positions' own accuracy (measured 1.6 m), not 30 m
}

// A platform that computes its frame centre itself — its own (noisy) GPS position and attitude, intersected with
// its terrain (here the level ground) — repeats the GPS error in every frame centre. Such frame centres agree
// with the positions (they share their error), so the χ² gate passes them; what must hold is that they do not
// make the result worse than the positions alone, nor claim an accuracy the positions do not have.
TEST(Georef, FrameCentresFromThePlatformsOwnGpsDoNotHurt) {
  // GPS error white (3 m per packet) or smooth (a 3 m drift at the orbit's period, which the positions alone
  // cannot tell from a 0.9° tilt, plus 0.5 m white).
  for (const bool smooth : {false, true}) {
    double rms[2], tilt[2];
    nlohmann::json with;
    for (int use = 0; use < 2; ++use) {
      GeorefCase g;
      const int n = 60;
      MakeGeorefCase(&g, n, smooth ? 0.5 : 3.0, false, -1, 1.0);
      io::FramesIndex index = io::ReadFramesIndex(g.dir / "frames/frames.json");
      const LocalFrame frame(kOrigin);
      for (size_t k = 0; k < index.frames.size(); ++k) {
        auto& f = index.frames[k];
        nlohmann::json t = core::ToJson(*f.telemetry);
        if (smooth) {
          const double a = 2 * M_PI * k / n;
          const Eigen::Vector3d drift = 3.0 * Eigen::Vector3d(std::sin(a + 1), std::cos(a + 2), std::sin(a));
          const GeoPoint p = frame.ToGeodetic(
              frame.ToEnu({t["sensor_latitude"], t["sensor_longitude"], t["sensor_altitude_hae"]}) + drift);
          t["sensor_latitude"] = p.lat, t["sensor_longitude"] = p.lon, t["sensor_altitude_hae"] = p.alt;
          t["sensor_altitude_msl"] = p.alt;
          f.telemetry = core::TelemetryFromJson(t);
        }
        telemetry::St0601Attitude a;
        a.platform_heading = t["platform_heading"], a.platform_pitch = t["platform_pitch"];
        a.platform_roll = t["platform_roll"];
        a.sensor_relative_azimuth = t["sensor_relative_azimuth"];
        a.sensor_relative_elevation = t["sensor_relative_elevation"];
        a.sensor_relative_roll = t["sensor_relative_roll"];
        const Eigen::Vector3d d = telemetry::CameraToEnuFromSt0601(a).col(2);
        const Eigen::Vector3d p = frame.ToEnu({t["sensor_latitude"], t["sensor_longitude"], t["sensor_altitude_hae"]});
        ASSERT_LT(d.z(), 0);
        const double range = -p.z() / d.z();
        const GeoPoint q = frame.ToGeodetic(p + range * d);
        f.telemetry->frame_center_latitude = q.lat;
        f.telemetry->frame_center_longitude = q.lon;
        f.telemetry->frame_center_elevation = q.alt;
        f.telemetry->slant_range = range;
      }
      io::WriteFramesIndex(index, g.dir / "frames/frames.json");
      GeorefOptions o;
      o.origin = kOrigin;
      o.use_frame_centres = use == 1;
      const auto j = RunGeorefStage(g.dir.path(), o);
      rms[use] = CentreRms(g);
      tilt[use] = RotationErrorDeg(g);
      if (use == 1) with = j;
    }
    std::cout << (smooth ? "smooth" : "white") << " GPS error: camera centres RMS / rotation error: positions "
              << rms[0] << " m / " << tilt[0] << "°, with the platform's frame centres " << rms[1] << " m / " << tilt[1]
              << "°; " << with["frame_centres"].dump() << "\n";
    EXPECT_LT(rms[1], 1.1 * rms[0]);
    EXPECT_LT(tilt[1], 1.1 * tilt[0] + 0.05);
    if (with["frame_centres"]["used"].get<bool>() && !smooth) {
      // The stated accuracy must not be below the positions' own (σ·√(3/N) ≈ 0.7 m): the frame centres add none.
      EXPECT_GT(with["frame_centres"]["expected_translation_error_m"].get<double>(), 0.5);
    }
  }
}

// Frame centres spread about the look-at point (a gimbal's jitter: 17 m at 140 m, as synth's orbits) and
// precise (1 cm): their own fit measures them at that precision, so they fix the whole rotation far below the
// 1° attitudes' floor — which the joint refinement reaches only when it weighs them by their own scatter, not
// by their scatter under the positions' rotation. georef.json's expected accuracy says so too.
TEST(Georef, SpreadFrameCentresFixTheRotation) {
  double angle[2];
  nlohmann::json acc[2];
  for (int use = 0; use < 2; ++use) {
    GeorefCase g;
    MakeGeorefCase(&g, 40, 3.0, false, -1, 1.0, 0, 200, 0, 0.01, Eigen::Vector3d::Zero(), 0, 17);
    GeorefOptions o;
    o.origin = kOrigin;
    o.use_frame_centres = use == 1;
    const auto j = RunGeorefStage(g.dir.path(), o);
    EXPECT_EQ(j["frame_centres"]["used"].get<bool>(), use == 1) << j["frame_centres"].dump();
    angle[use] = RotationErrorDeg(g);
    acc[use] = j["expected_accuracy"];
  }
  std::cout << "rotation error: positions + attitudes " << angle[0] << "° (expected tilt " << acc[0]["tilt_deg"]
            << "°), + frame centres " << angle[1] << "° (expected " << acc[1]["tilt_deg"] << "°)\n";
  EXPECT_GT(angle[0], 0.05);
  EXPECT_LT(angle[1], 0.01);
  // The expected tilt follows: near the attitudes' floor (1°/√40 per axis) without, far below it with.
  EXPECT_NEAR(acc[0]["tilt_deg"].get<double>(), std::sqrt(2.0) / std::sqrt(40.0), 0.08);
  EXPECT_LT(acc[1]["tilt_deg"].get<double>(), 0.02);
  EXPECT_EQ(acc[1]["from"].size(), 3u);
}

// A frame centre's height comes as two 2-byte codes, MSL (tag 25) and HAE (tag 78), each 0.30 m steps. synth's
// ground at 60.000 m HAE is 4 mm under a step boundary: the HAE code alone says 59.852 (−0.148 m). With the MSL
// code and the undulation (here −33.874, EGM96 there; estimated from the sensor's two heights) the truth lies in
// the intersection of the two steps, [59.831, 60.004]: its middle is −0.083 m off, not −0.148.
TEST(Georef, FrameCentreHeightsInBothDatumsNarrowTheStep) {
  const double step = 19900.0 / 65535, n_geoid = -33.874;
  const auto code = [&](double h) { return std::round((h + 900) / step) * step - 900; };
  double vertical[2];
  for (int both = 0; both < 2; ++both) {
    GeorefCase g;
    MakeGeorefCase(&g, 40, 3.0, false, -1, 1.0, 0, 200, 0, 0.0, Eigen::Vector3d::Zero(), 0, 17);
    io::FramesIndex index = io::ReadFramesIndex(g.dir / "frames/frames.json");
    for (auto& f : index.frames) {
      nlohmann::json t = core::ToJson(*f.telemetry);
      const double hae = t["frame_center_elevation"].get<double>();  // written true (HAE = MSL) by the case
      t.erase("frame_center_elevation");
      t["frame_center_hae"] = code(hae);
      // The sensor's heights are 2-byte codes too (tags 75, 15): N is estimated from them, to ~2 cm here.
      const double sensor = t["sensor_altitude_hae"].get<double>();
      t["sensor_altitude_hae"] = code(sensor);
      t["sensor_altitude_msl"] = code(sensor - n_geoid);
      if (both) t["frame_center_elevation"] = code(hae - n_geoid);
      f.telemetry = core::TelemetryFromJson(t);
    }
    io::WriteFramesIndex(index, g.dir / "frames/frames.json");
    GeorefOptions o;
    o.origin = kOrigin;
    const auto j = RunGeorefStage(g.dir.path(), o);
    ASSERT_TRUE(j["frame_centres"]["used"].get<bool>()) << j["frame_centres"].dump();
    const core::Reconstruction enu = io::ReadColmapText(g.dir / "geo/sparse_enu");
    double dz = 0;
    for (const auto& [id, img] : enu.images) dz += img.pose.Centre().z() - g.true_centres[id - 1].z();
    vertical[both] = dz / enu.images.size();
    if (both) {
      const double sigma_n = j["frame_centres"]["geoid_undulation_sigma_m"].get<double>();
      EXPECT_NEAR(j["frame_centres"]["geoid_undulation_m"].get<double>(), n_geoid, 3 * sigma_n + 1e-3);
      EXPECT_GT(sigma_n, 0.005);
      EXPECT_LT(sigma_n, 0.05);
      // The offset's prior: uniform over 0.173 m (σ 0.050), its MSL edge blurred by N's σ; one step is σ 0.088.
      EXPECT_GT(j["frame_centres"]["elevation_offset_prior_sd_m"].get<double>(), 0.045);
      EXPECT_LT(j["frame_centres"]["elevation_offset_prior_sd_m"].get<double>(), 0.065);
    } else {
      EXPECT_NEAR(j["frame_centres"]["elevation_offset_prior_sd_m"].get<double>(), step / std::sqrt(12.0), 0.002);
    }
  }
  std::cout << "mean vertical error: HAE code only " << vertical[0] << " m, HAE and MSL codes " << vertical[1]
            << " m\n";
  // Each stays inside its interval (the positions, σ 3 m over 40 packets, weigh where): HAE alone [−0.30, +0.004],
  // both [−0.169, +0.004]; measured −0.195 and −0.096.
  EXPECT_GT(vertical[0], -0.32);
  EXPECT_GT(vertical[1], -0.19);
  EXPECT_LT(vertical[1], 0.02);
  EXPECT_LT(std::abs(vertical[1]), std::abs(vertical[0]) - 0.05);
}

// A straight track over ground that is not level: the level-ground roll is 4° off, and the frame centres
// (beside the track) put it right.
TEST(Georef, FrameCentresFixTheRollAboutAStraightTrack) {
  double angle[2];
  for (int use = 0; use < 2; ++use) {
    GeorefCase g;
    MakeGeorefCase(&g, 30, 1.0, true, -1, -1, 0, 200, 0, 0.05, Eigen::Vector3d::Zero(), 4.0);
    GeorefOptions o;
    o.use_frame_centres = use == 1;
    const auto j = RunGeorefStage(g.dir.path(), o);
    EXPECT_EQ(j["frame_centres"]["used"].get<bool>(), use == 1) << j["frame_centres"].dump();
    angle[use] = RotationErrorDeg(g);
  }
  std::cout << "rotation error: level ground " << angle[0] << "°, frame centres " << angle[1] << "°\n";
  EXPECT_GT(angle[0], 2.0);
  EXPECT_LT(angle[1], 0.2) << "level ground: " << angle[0];
}

// A straight pass whose image model twists about the track (each camera rolled about it, 0 → 0.6° along it) while
// every camera stays on the line: the positions fit it perfectly and the level ground hides the twist, but the
// frame centres (1 cm, spread 17 m) see it. --constrain auto builds the model again with them as priors and
// keeps it; the cameras' orientations come out right. With --constrain never the twist stays.
double WorstOrientationErrorDeg(const GeorefCase& g) {
  const core::Reconstruction enu = io::ReadColmapText(g.dir / "geo/sparse_enu");
  double worst = 0;
  for (const auto& [id, img] : enu.images) {
    const core::Pose truth = core::Pose::LookAt(g.true_centres[id - 1], CaseLookAt(id - 1, 17));
    worst = std::max(worst, core::RotationAngle(img.pose.q, truth.q) * 180 / M_PI);
  }
  return worst;
}

TEST(Georef, StraightTrackWithFrameCentresIsBuiltAgain) {
  double worst[2];
  for (int mode = 0; mode < 3; ++mode) {
    GeorefCase g;
    const int n = 30;
    MakeGeorefCase(&g, n, 3.0, true, -1, -1, 0, 200, 0, 0.01, Eigen::Vector3d::Zero(), 0, 17);
    ObserveAndBend(&g, n, 17, 0);
    core::Reconstruction rec = io::ReadColmapText(g.dir / "sparse");
    const Eigen::Vector3d track = g.true_to_model.q * Eigen::Vector3d::UnitX();
    for (auto& [id, img] : rec.images) {
      const double roll = 0.6 * M_PI / 180 * (id - 1) / (n - 1);
      const Eigen::Vector3d c = img.pose.Centre();
      img.pose.q = (img.pose.q * Eigen::Quaterniond(Eigen::AngleAxisd(roll, track))).normalized();
      img.pose.t = -(img.pose.q * c);
    }
    if (mode == 2) {
      // The telemetry's HFOV is 5% off and the image model is sound: the rebuild, which holds the HFOV camera,
      // explains the images worse than the image model and is not kept.
      for (auto& [id, img] : rec.images)
        img.pose = g.true_to_model.Apply(core::Pose::LookAt(g.true_centres[id - 1], CaseLookAt(id - 1, 17)));
      io::FramesIndex index = io::ReadFramesIndex(g.dir / "frames/frames.json");
      index.cameras[0].prior_source = fmv3d::io::ParsePriorSource("telemetry-hfov");
      index.cameras[0].camera.f *= 1.05;
      io::WriteFramesIndex(index, g.dir / "frames/frames.json");
    }
    io::WriteColmapText(rec, g.dir / "sparse");
    GeorefOptions o;
    o.origin = kOrigin;
    o.constrain = mode == 0 ? GeorefOptions::Constrain::kNever : GeorefOptions::Constrain::kAuto;
    const auto j = RunGeorefStage(g.dir.path(), o);
    EXPECT_NE(j["rotation_about_track_from"].get<std::string>().find("ground"), std::string::npos);
    if (mode == 2) {
      const auto& t = j["telemetry_constrained"];
      EXPECT_FALSE(t.value("applied", true)) << t.dump();
      EXPECT_GT(t.value("reprojection_rms_px", 0.0), 1.5 * t.value("reprojection_rms_px_image_only", 0.0) + 0.1)
          << t.dump();
      continue;
    }
    if (mode == 1) {
      const auto& t = j["telemetry_constrained"];
      EXPECT_TRUE(t.value("applied", false)) << t.dump();
      EXPECT_EQ(t.value("trigger", ""), "a nearly straight track with frame centres") << t.dump();
      EXPECT_TRUE(j["frame_centres"]["used"].get<bool>()) << j["frame_centres"].dump();
    }
    worst[mode] = WorstOrientationErrorDeg(g);
  }
  std::cout << "worst camera orientation error: image model " << worst[0] << "°, rebuilt " << worst[1] << "°\n";
  EXPECT_GT(worst[0], 0.2);
  EXPECT_LT(worst[1], 0.1);
}

// An image model whose pointing is off (every camera pitched 1°, centres right: the track fits) makes the frame
// centres disagree with it. Here the frame centres also carry a common 2 m offset in height, so they disagree
// with the positions whatever the model: the rebuild cannot make them agree, but it removes far more of their
// disagreement than the agreement band (χ² 253 → 62; the band is 18.5) and explains the images, so it is kept,
// and its cameras point within 0.2° (1.04° in the image model).
TEST(Georef, RebuildThatDisagreesFarLessIsKept) {
  double worst[2];
  for (int mode = 0; mode < 2; ++mode) {
    GeorefCase g;
    const int n = 40;
    MakeGeorefCase(&g, n, 3.0, false, -1, 0.5, 0, 200, 0, 0.01, Eigen::Vector3d(0, 0, 2), 0, 17);
    ObserveAndBend(&g, n, 17, 0);
    core::Reconstruction rec = io::ReadColmapText(g.dir / "sparse");
    for (auto& [id, img] : rec.images) {
      const Eigen::Vector3d c = img.pose.Centre();
      img.pose.q =
          (Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 180, Eigen::Vector3d::UnitX())) * img.pose.q).normalized();
      img.pose.t = -(img.pose.q * c);
    }
    io::WriteColmapText(rec, g.dir / "sparse");
    GeorefOptions o;
    o.origin = kOrigin;
    o.constrain = mode == 0 ? GeorefOptions::Constrain::kNever : GeorefOptions::Constrain::kAuto;
    const auto j = RunGeorefStage(g.dir.path(), o);
    EXPECT_EQ(j["fit_fraction"].get<double>(), 1.0);
    EXPECT_FALSE(j["frame_centres"]["used"].get<bool>()) << j["frame_centres"].dump();
    if (mode == 1) {
      const auto& t = j["telemetry_constrained"];
      EXPECT_TRUE(t.value("applied", false)) << t.dump();
      EXPECT_EQ(t.value("trigger", ""), "the frame centres disagree with the model") << t.dump();
      EXPECT_GT(t.value("frame_centres_chi2", 0.0), kFrameCentreAgreementChi2) << t.dump();
      EXPECT_LT(t.value("frame_centres_chi2", 1e9),
                t.value("frame_centres_chi2_image_only", 0.0) - kFrameCentreAgreementChi2)
          << t.dump();
    }
    worst[mode] = WorstOrientationErrorDeg(g);
  }
  std::cout << "worst camera orientation error: image model " << worst[0] << "°, rebuilt " << worst[1] << "°\n";
  EXPECT_GT(worst[0], 0.8);
  EXPECT_LT(worst[1], 0.2);  // 0.13°: the offset frame centres still pull a little
}

TEST(Georef, ClearErrors) {
  test::TempDir dir("georef-err");
  EXPECT_THROW(RunGeorefStage(dir.path()), Error);
  GeorefCase g;
  MakeGeorefCase(&g, 10, 0, false, -1);
  io::FramesIndex index = io::ReadFramesIndex(g.dir / "frames/frames.json");
  for (auto& f : index.frames) f.telemetry.reset();
  io::WriteFramesIndex(index, g.dir / "frames/frames.json");
  try {
    RunGeorefStage(g.dir.path());
    FAIL() << "no telemetry must be an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("telemetry"), std::string::npos) << e.what();
  }
}

// A 20 x 10 m box of height 12 m on a 100 x 100 m ground plane, written as WS/mesh/poisson.ply in a
// workspace georeferenced with a known similarity.
void MakeDsmWorkspace(const test::TempDir& dir, const core::Sim3& enu_to_model) {
  open3d::geometry::TriangleMesh mesh;
  auto quad = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                  const Eigen::Vector3d& d) {
    const int i = static_cast<int>(mesh.vertices_.size());
    for (const auto& v : {a, b, c, d}) mesh.vertices_.push_back(enu_to_model.Apply(v));
    mesh.triangles_.push_back({i, i + 1, i + 2});
    mesh.triangles_.push_back({i, i + 2, i + 3});
  };
  // Ground (with a hole under the box is unnecessary: the roof is higher and wins).
  for (int x = -50; x < 50; x += 10)
    for (int y = -50; y < 50; y += 10)
      quad({x * 1.0, y * 1.0, 0}, {x + 10.0, y * 1.0, 0}, {x + 10.0, y + 10.0, 0}, {x * 1.0, y + 10.0, 0});
  quad({-10, -5, 12}, {10, -5, 12}, {10, 5, 12}, {-10, 5, 12});  // roof
  quad({-10, -5, 0}, {10, -5, 0}, {10, -5, 12}, {-10, -5, 12});  // a wall
  core::EnsureDirectory(dir / "mesh");
  ASSERT_TRUE(open3d::io::WriteTriangleMesh((dir / "mesh/poisson.ply").string(), mesh));
  // A sparse model with a few coloured points (for the LAS and the ortho fallback).
  core::Reconstruction rec;
  for (int i = 0; i < 100; ++i) {
    core::Point3D p;
    p.id = i + 1;
    p.xyz = enu_to_model.Apply(Eigen::Vector3d(-45 + i * 0.9, 10, 0));
    p.rgb << 200, 100, 50;
    rec.points[p.id] = p;
  }
  io::WriteColmapText(rec, dir / "sparse");
  const core::Sim3 model_to_enu = enu_to_model.Inverse();
  const Eigen::Quaterniond q = model_to_enu.q;
  nlohmann::json j;
  j["origin"] = {{"lat", kOrigin.lat}, {"lon", kOrigin.lon}, {"alt", kOrigin.alt}};
  j["vertical_datum"] = "WGS84 ellipsoid";
  j["similarity"] = {{"scale", model_to_enu.s},
                     {"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                     {"translation", {model_to_enu.t.x(), model_to_enu.t.y(), model_to_enu.t.z()}}};
  j["utm"] = {{"zone", 18}, {"north", true}};
  core::EnsureDirectory(dir / "geo");
  core::WriteJson(dir / "geo/georef.json", j);
}

// dsm.json states the absolute height error georef expects over its cells (geo/accuracy.h): 0.1 m of vertical
// translation, and a 1 mrad tilt about east that grows with the northing (cells span ±50 m: E[y²] = 100²/12).
TEST(Dsm, ExpectedHeightErrorFromTheGeoreference) {
  test::TempDir dir("dsm-acc");
  core::Sim3 enu_to_model;
  MakeDsmWorkspace(dir, enu_to_model);
  DsmOptions o;
  o.gsd = 0.5;
  o.write_las = false;
  auto j = RunDsmStage(dir.path(), o);
  EXPECT_TRUE(j["expected_height_error_m"].is_null());
  EXPECT_NE(j["expected_height_error_why"].get<std::string>().find("no expected accuracy"), std::string::npos);
  nlohmann::json g = core::ReadJson(dir / "geo/georef.json");
  GeorefAccuracy acc;
  acc.pivot = Eigen::Vector3d(0, 0, 0);
  acc.position_cov = Eigen::Vector3d(0.04, 0.04, 0.01).asDiagonal();
  g["expected_accuracy"] = acc.ToJson();
  core::WriteJson(dir / "geo/georef.json", g);
  j = RunDsmStage(dir.path(), o);
  EXPECT_NEAR(j["expected_height_error_m"].get<double>(), 0.1, 1e-6);
  acc.rotation_cov(0, 0) = 1e-6;
  g["expected_accuracy"] = acc.ToJson();
  core::WriteJson(dir / "geo/georef.json", g);
  j = RunDsmStage(dir.path(), o);
  EXPECT_NEAR(j["expected_height_error_m"].get<double>(), std::sqrt(0.01 + 1e-6 * 100.0 * 100.0 / 12), 0.002);
  // A rotation the georeference could not fix: no figure, and why.
  acc.rotation_known = false;
  g["expected_accuracy"] = acc.ToJson();
  core::WriteJson(dir / "geo/georef.json", g);
  j = RunDsmStage(dir.path(), o);
  EXPECT_TRUE(j["expected_height_error_m"].is_null());
  EXPECT_NE(j["expected_height_error_why"].get<std::string>().find("rotation unknown"), std::string::npos);
}

TEST(Dsm, MeshRasterisedToHighestSurfaceInUtm) {
  test::TempDir dir("dsm");
  core::Sim3 enu_to_model;
  enu_to_model.s = 0.2;
  enu_to_model.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()));
  enu_to_model.t = Eigen::Vector3d(5, 6, 7);
  MakeDsmWorkspace(dir, enu_to_model);
  DsmOptions o;
  o.gsd = 0.5;
  const auto j = RunDsmStage(dir.path(), o);
  EXPECT_EQ(j["epsg"].get<int>(), 32618);
  GridSpec grid;
  const cv::Mat h = ReadHeightGeoTiff(dir / "geo/dsm.tif", &grid);
  EXPECT_EQ(grid.zone.Epsg(), 32618);
  EXPECT_DOUBLE_EQ(grid.gsd, 0.5);
  // Sample the roof centre and open ground through the ENU → UTM mapping.
  const LocalFrame frame(kOrigin);
  auto height_at = [&](const Eigen::Vector3d& enu) {
    const Eigen::Vector3d u = frame.EnuToUtm(enu);
    const int r = static_cast<int>(grid.Row(u.y())), c = static_cast<int>(grid.Col(u.x()));
    return h.at<float>(r, c);
  };
  // Ellipsoidal heights: origin alt + z, less the Earth's curvature (< 1 mm within 50 m).
  EXPECT_NEAR(height_at({0, 0, 12}), 72.0, 0.01);
  EXPECT_NEAR(height_at({3, -2, 12}), 72.0, 0.01);
  EXPECT_NEAR(height_at({30, 30, 0}), 60.0, 0.01);
  EXPECT_NEAR(height_at({-40, 20, 0}), 60.0, 0.01);
  // Outside the mesh: no data.
  EXPECT_TRUE(std::isnan(h.at<float>(0, 0)));
  const std::string info = GdalInfo(dir / "geo/dsm.tif");
  EXPECT_NE(info.find("UTM zone 18N"), std::string::npos) << info;
  EXPECT_NE(info.find("NoData Value=-9999"), std::string::npos) << info;
  EXPECT_TRUE(std::filesystem::exists(dir / "geo/hillshade.png"));
  // LAS: the sparse points with the UTM CRS, at the right place.
  const LasInfo las = ReadLas(dir / "geo/points.las", true);
  EXPECT_EQ(las.version_minor, 4);
  EXPECT_EQ(las.point_format, 7);
  EXPECT_EQ(las.num_points, 100u);
  EXPECT_NE(las.wkt.find("UTM zone 18N"), std::string::npos);
  const Eigen::Vector3d first = frame.EnuToUtm({-45, 10, 0});
  EXPECT_LT((las.points[0] - first).norm(), 0.002);
  // The creation day: the clock's, or SOURCE_DATE_EPOCH's (2023-11-14 22:13:20 GMT: day 318).
  std::tm today{};
  const std::time_t now = std::time(nullptr);
  gmtime_r(&now, &today);
  EXPECT_GE(las.creation_year, 2025);
  EXPECT_LE(las.creation_year, today.tm_year + 1900);
  ASSERT_EQ(setenv("SOURCE_DATE_EPOCH", "1700000000", 1), 0);
  WriteLas(dir / "dated.las", las.points, {}, las.wkt);
  unsetenv("SOURCE_DATE_EPOCH");
  const LasInfo dated = ReadLas(dir / "dated.las");
  EXPECT_EQ(dated.creation_day, 318);
  EXPECT_EQ(dated.creation_year, 2023);
  // Orthophoto: no textured mesh, so the coloured points; the grid is the DSM's.
  const auto oj = RunOrthoStage(dir.path());
  EXPECT_GT(oj["valid_cells"].get<int>(), 50);
  EXPECT_EQ(oj["width"].get<int>(), grid.width);
}

// A mesh checked against its points: ground at 100 m (4 points per cell, ±5 cm), a roof block at 110 m, a
// Poisson membrane sloping down from the roof's edge over ground the points measured, a blob floating over
// measured ground, a dip, far land whose points state a large σ, and a patch with no points.
TEST(Dsm, MeshHeightsTheirPointsContradictAreReplaced) {
  GridSpec grid;
  grid.min_e = 0, grid.max_n = 40, grid.gsd = 1, grid.width = 40, grid.height = 40;
  cv::Mat mesh(40, 40, CV_32F, cv::Scalar(100.0f));
  std::vector<Eigen::Vector3d> points;
  std::vector<float> sigma;
  const auto roof = [](int r, int c) { return r >= 10 && r < 20 && c >= 10 && c < 20; };
  const auto far = [](int r, int c) { return r < 5 && c >= 30 && c < 35; };
  const auto blob = [](int r, int c) { return r >= 30 && r < 33 && c >= 30 && c < 33; };
  const auto empty = [](int r, int c) { return r >= 35 && c < 5; };
  for (int r = 0; r < 40; ++r)
    for (int c = 0; c < 40; ++c) {
      if (empty(r, c)) {
        mesh.at<float>(r, c) = 108;
        continue;
      }
      for (int k = 0; k < 4; ++k) {
        const double e = c + 0.25 + 0.5 * (k % 2), n = 40 - (r + 0.25 + (k >= 2 ? 0.5 : 0.0));
        const double wobble = 0.05 * std::sin(7.0 * (r * 40 + c) + k);
        points.emplace_back(e, n, (roof(r, c) ? 110.0 : 100.0) + wobble);
        sigma.push_back(far(r, c) ? 5.0f : 0.1f);
      }
      if (blob(r, c)) {  // the outlier points the blob was fitted to
        points.emplace_back(c + 0.5, 40 - (r + 0.5), 108.0);
        sigma.push_back(0.1f);
      }
      if (roof(r, c)) mesh.at<float>(r, c) = 110;
      if (blob(r, c)) mesh.at<float>(r, c) = 108;
      if (far(r, c)) mesh.at<float>(r, c) = 103;
    }
  for (int r = 10; r < 20; ++r) mesh.at<float>(r, 20) = 107, mesh.at<float>(r, 21) = 104, mesh.at<float>(r, 22) = 102;
  mesh.at<float>(25, 5) = 95;
  mesh.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();

  MeshCheckStats st;
  const cv::Mat h = CheckMeshHeights(mesh, points, sigma, grid, {}, &st);
  EXPECT_TRUE(std::isnan(h.at<float>(0, 0)));
  for (int r = 10; r < 20; ++r) {
    EXPECT_EQ(h.at<float>(r, 10), 110.0f) << r;  // the roof, its edges included
    EXPECT_EQ(h.at<float>(r, 19), 110.0f) << r;
    if (r == 10 || r == 19)  // the roof is under a quarter of the window: replaced
      EXPECT_NEAR(h.at<float>(r, 20), 100.0f, 0.06) << r;
    else  // a third of the window is roof: one cell of membrane stays
      EXPECT_EQ(h.at<float>(r, 20), 107.0f) << r;
    EXPECT_NEAR(h.at<float>(r, 21), 100.0f, 0.06) << r;
    EXPECT_NEAR(h.at<float>(r, 22), 100.0f, 0.06) << r;
  }
  for (int r = 30; r < 33; ++r)
    for (int c = 30; c < 33; ++c) EXPECT_NEAR(h.at<float>(r, c), 100.0f, 0.06) << r << "," << c;
  EXPECT_NEAR(h.at<float>(25, 5), 100.0f, 0.06);
  EXPECT_EQ(h.at<float>(2, 32), 103.0f);  // within the far land's stated σ
  // The patch without points: where any point lies within max_gap (3 cells), the mesh stands above all of
  // them (a roof carried over unseen ground) and takes their median; beyond, it is left without data.
  for (int r = 35; r < 40; ++r)
    for (int c = 0; c < 5; ++c) {
      if (r >= 38 && c < 2)
        EXPECT_TRUE(std::isnan(h.at<float>(r, c))) << r << "," << c;
      else
        EXPECT_NEAR(h.at<float>(r, c), 100.0f, 0.06) << r << "," << c;
    }
  EXPECT_EQ(st.unmeasured, 4u);
  EXPECT_EQ(h.at<float>(5, 5), 100.0f);  // agreeing ground untouched
  // 2 + 10 + 10 membrane cells, 9 blob cells, the far patch's two bottom corners (its points under half of the
  // window: the median σ is the near ground's), the 9 rim cells of the patch without points, whose windows
  // reach measured ground, and its 12 other cells with a point within max_gap.
  EXPECT_EQ(st.replaced_above, 54u);
  EXPECT_EQ(st.replaced_below, 1u);
  EXPECT_THROW(CheckMeshHeights(mesh, points, std::vector<float>(3, 1.0f), grid, {}, &st), Error);
}

TEST(Dsm, OrthoFromTexturedMesh) {
  test::TempDir dir("ortho");
  MakeDsmWorkspace(dir, core::Sim3());
  RunDsmStage(dir.path(), {});
  // A single textured quad over the box's footprint: left half red, right half blue.
  io::TexturedMesh mesh;
  mesh.vertices = {{-10, -5, 20}, {10, -5, 20}, {10, 5, 20}, {-10, 5, 20}};
  mesh.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  io::Material m;
  m.name = "tex";
  m.texture_file = "tex.png";
  m.texture = cv::Mat(8, 8, CV_8UC3, cv::Scalar(255, 0, 0));
  m.texture(cv::Rect(0, 0, 4, 8)).setTo(cv::Scalar(0, 0, 255));
  mesh.materials.push_back(m);
  io::Face f1, f2;
  f1.v[0] = 0, f1.v[1] = 1, f1.v[2] = 2, f1.vt[0] = 0, f1.vt[1] = 1, f1.vt[2] = 2, f1.material = 0;
  f2.v[0] = 0, f2.v[1] = 2, f2.v[2] = 3, f2.vt[0] = 0, f2.vt[1] = 2, f2.vt[2] = 3, f2.material = 0;
  mesh.faces = {f1, f2};
  io::WriteObj(mesh, dir / "mesh/textured.obj");
  const auto j = RunOrthoStage(dir.path());
  EXPECT_GT(j["valid_cells"].get<int>(), 0);
  EXPECT_EQ(j["source"].get<std::string>(), (dir / "mesh/textured.obj").string());
  // West half red, east half blue (the texture's left and right), transparent outside the quad.
  GridSpec grid;
  ReadHeightGeoTiff(dir / "geo/dsm.tif", &grid);
  const LocalFrame frame(kOrigin);
  auto cell = [&](double e, double n) {
    const Eigen::Vector3d u = frame.EnuToUtm({e, n, 20});
    return std::pair<int, int>(static_cast<int>(grid.Row(u.y())), static_cast<int>(grid.Col(u.x())));
  };
  const fs::path ortho = dir / "geo/ortho.tif";
  const auto [rw, cw] = cell(-5, 0);
  const auto [re, ce] = cell(5, 0);
  const auto [ro, co] = cell(30, 30);
  EXPECT_EQ(Pixel(ortho, 1, rw, cw), 255);
  EXPECT_EQ(Pixel(ortho, 3, rw, cw), 0);
  EXPECT_EQ(Pixel(ortho, 1, re, ce), 0);
  EXPECT_EQ(Pixel(ortho, 3, re, ce), 255);
  EXPECT_EQ(Pixel(ortho, 4, re, ce), 255);
  EXPECT_EQ(Pixel(ortho, 4, ro, co), 0);
}

TEST(Dsm, NeedsGeoref) {
  test::TempDir dir("dsm-err");
  try {
    RunDsmStage(dir.path(), {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fmv3d georef"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace fmv3d::geo
