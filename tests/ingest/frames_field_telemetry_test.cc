// End to end: `fmv3d synth` writes EXIF-GPS JPEG frames and a GPMF MP4 from the truth cameras with GPS and
// attitude noise; `fmv3d frames` reads them back into frames.json; the per-frame telemetry must match the
// truth within the noise, and corrupt metadata must be dropped, never used.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <functional>
#include <iterator>

#include "fmv3d/ingest/frames.h"
#include "fmv3d/io/exif_writer.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/synth/synth.h"
#include "fmv3d/telemetry/attitude.h"
#include "test_util.h"

namespace fmv3d::ingest {
namespace {

synth::SynthOptions SmallFlight(const std::filesystem::path& out, synth::OutputFormat format) {
  synth::SynthOptions o;
  o.scene = synth::SceneKind::kBuilding;
  o.flight.frames = 12;
  o.width = 192;
  o.height = 112;
  o.format = format;
  o.fps = 5;
  o.truth_points = 0;
  o.write_scene = false;
  o.render.supersample = 1;
  o.detail = 0.25;
  o.klv_options.gps_noise = 2.0;
  o.klv_options.attitude_noise = 0.5;
  o.klv_options.geoid_undulation = -33.87;
  o.output = out;
  return o;
}

// Per-axis RMS (m) of the telemetry positions (ellipsoidal heights) against the truth camera centres.
double PositionRms(const io::FramesIndex& index, const synth::SynthResult& r, const synth::SynthOptions& o,
                   double undulation_to_add) {
  double sq = 0;
  size_t n = 0;
  for (size_t k = 0; k < index.frames.size(); ++k) {
    const auto& f = index.frames[k];
    const nlohmann::json t = core::ToJson(*f.telemetry);
    const double alt = t.contains("sensor_altitude_hae")
                           ? t.at("sensor_altitude_hae").get<double>()
                           : t.at("sensor_altitude_msl").get<double>() + undulation_to_add;
    const synth::GeoPoint g{t.at("sensor_latitude").get<double>(), t.at("sensor_longitude").get<double>(), alt};
    const Eigen::Vector3d enu = synth::GeodeticToEnu(g, o.klv_options.origin);
    // Video frames by their index, photos (frame_index 0) by their position: both name the truth image.
    const auto id = static_cast<uint32_t>((f.frame_index > 0 ? static_cast<size_t>(f.frame_index) : k) + 1);
    sq += (enu - r.truth.images.at(id).pose.Centre()).squaredNorm();
    ++n;
  }
  return std::sqrt(sq / (3.0 * n));
}

TEST(FieldTelemetry, SynthExifJpegsThroughFrames) {
  test::TempDir dir("synth-exif");
  synth::SynthOptions o = SmallFlight(dir.path(), synth::OutputFormat::kJpg);
  o.exif_gps = true;
  const auto result = synth::RunSynth(o);
  // Through the CLI, so that the EXIF focal prior is wired as a user gets it.
  const auto frames = test::RunCli("frames " + (dir / "frames").string() + " -o " + (dir / "ws").string());
  ASSERT_EQ(frames.exit_code, 0) << frames.err;
  const io::FramesIndex index = io::ReadFramesIndex(dir / "ws/frames/frames.json");
  ASSERT_EQ(index.frames.size(), 12u);
  for (size_t k = 0; k < index.frames.size(); ++k) {
    const auto& f = index.frames[k];
    ASSERT_TRUE(f.telemetry.has_value()) << f.name;
    EXPECT_EQ(f.telemetry->source, "EXIF+DJI-XMP");
    const auto& r = result.klv.at(k);  // frames are named in order
    EXPECT_NEAR(f.telemetry->sensor_latitude.value_or(NAN), r.sensor_latitude, 3e-8) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_longitude.value_or(NAN), r.sensor_longitude, 3e-8) << f.name;
    EXPECT_NEAR(f.telemetry->sensor_altitude_msl.value_or(NAN), r.sensor_true_altitude, 1e-6) << f.name;
    // The stated attitude reproduces the truth camera within the attitude noise (0.5° per platform angle).
    const nlohmann::json t = core::ToJson(*f.telemetry);
    auto num = [&](const char* key) { return t.at(key).get<double>(); };
    const telemetry::St0601Attitude a{num("platform_heading"),
                                      num("platform_pitch"),
                                      num("platform_roll"),
                                      num("sensor_relative_azimuth"),
                                      num("sensor_relative_elevation"),
                                      num("sensor_relative_roll")};
    const Eigen::Matrix3d truth = result.truth.images.at(static_cast<uint32_t>(k + 1)).pose.R().transpose();
    const double err = Eigen::AngleAxisd(truth.transpose() * telemetry::CameraToEnuFromSt0601(a)).angle() * 180 / M_PI;
    EXPECT_LT(err, 4 * 0.5 * std::sqrt(3.0)) << f.name;
    const Eigen::Matrix3d g =
        telemetry::CameraToEnuFromGimbal(num("gimbal_yaw"), num("gimbal_pitch"), num("gimbal_roll"));
    EXPECT_LT((g - telemetry::CameraToEnuFromSt0601(a)).norm(), 1e-6) << f.name;
  }
  const double rms = PositionRms(index, result, o, o.klv_options.geoid_undulation);
  EXPECT_GT(rms, 0.8);  // the noise is there
  EXPECT_LT(rms, 3.5);  // and about as large as stated (2 m per axis)
  // The focal prior comes from the EXIF focal length and focal-plane resolution (exact to the rationals' 1e-3),
  // not the guess nor the 35 mm equivalent (rounded to whole mm: 1-2% off).
  ASSERT_EQ(index.cameras.size(), 1u);
  EXPECT_EQ(fmv3d::io::PriorSourceName(index.cameras[0].prior_source), "exif");
  EXPECT_NEAR(index.cameras[0].camera.f, result.truth.cameras.at(1).f, 2e-4 * result.truth.cameras.at(1).f);

  // `fmv3d telemetry` dumps the same sample for one photo.
  const auto cli = test::RunCli("telemetry " + (dir / "frames" / "flight-000003.jpg").string());
  ASSERT_EQ(cli.exit_code, 0) << cli.err;
  const auto j = nlohmann::json::parse(cli.out);
  EXPECT_EQ(j.at("kind"), "photo");
  EXPECT_EQ(j.at("telemetry").at("sensor_latitude"), index.frames[3].telemetry->sensor_latitude.value_or(NAN));
}

TEST(FieldTelemetry, CorruptPhotoMetadataIsDroppedWithACount) {
  test::TempDir dir("synth-exif-bad");
  synth::SynthOptions o = SmallFlight(dir.path(), synth::OutputFormat::kJpg);
  o.flight.frames = 4;
  o.exif_gps = true;
  synth::RunSynth(o);
  // Frame 1: a (0, 0) fix; frame 2: garbage in the EXIF block and the XMP; frame 3: no lock (GPSStatus V).
  auto rewrite = [&](int k, const std::function<void(std::vector<uint8_t>*)>& spoil) {
    const auto path = dir / "frames" / synth::FrameName(k, "jpg");
    std::ifstream in(path, std::ios::binary);
    std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    in.close();
    spoil(&bytes);
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  };
  auto plain = [](std::vector<uint8_t>* b) {  // the JPEG without its metadata segments
    std::vector<uint8_t> out = {0xFF, 0xD8};
    size_t pos = 2;
    while (pos + 4 <= b->size() && (*b)[pos] == 0xFF && (*b)[pos + 1] == 0xE1)
      pos += 2 + ((*b)[pos + 2] << 8 | (*b)[pos + 3]);
    out.insert(out.end(), b->begin() + static_cast<long>(pos), b->end());
    return out;
  };
  rewrite(1, [&](std::vector<uint8_t>* b) {
    io::ExifInfo e;
    e.gps.latitude = 0.0;
    e.gps.longitude = 0.0;
    e.gps.altitude = 100.0;
    *b = io::InsertJpegMetadata(plain(b), io::EncodeTiffExif(e), "");
  });
  rewrite(2, [&](std::vector<uint8_t>* b) {
    for (size_t i = 30; i < 400 && i < b->size(); i += 3) (*b)[i] ^= 0x5A;  // inside the EXIF block
    *b = io::InsertJpegMetadata(plain(b), {'I', 'I', 42, 0, 0xFF, 0xFF, 0xFF, 0x7F},
                                "drone-dji:AbsoluteAltitude=\"1e999\" drone-dji:GimbalYawDegree=\"--\"");
  });
  rewrite(3, [&](std::vector<uint8_t>* b) {
    io::ExifInfo e;
    e.gps.latitude = 38.16;
    e.gps.longitude = -77.35;
    e.gps.status = 'V';
    *b = io::InsertJpegMetadata(plain(b), io::EncodeTiffExif(e), "");
  });
  IngestOptions io_opts;
  io_opts.workspace = dir / "ws";
  const io::FramesIndex index = IngestFrames({dir / "frames"}, io_opts);
  ASSERT_EQ(index.frames.size(), 4u);  // every photo kept
  EXPECT_TRUE(index.frames[0].telemetry.has_value());
  for (int k = 1; k < 4; ++k) EXPECT_FALSE(index.frames[k].telemetry.has_value()) << k;
}

TEST(FieldTelemetry, SynthGpmfMp4ThroughFrames) {
  for (const bool gps9 : {false, true}) {
    test::TempDir dir("synth-gpmf");
    synth::SynthOptions o = SmallFlight(dir.path(), synth::OutputFormat::kMp4);
    o.gpmf = true;
    o.gpmf_gps9 = gps9;
    const auto result = synth::RunSynth(o);
    IngestOptions io_opts;
    io_opts.workspace = dir / "ws";
    io_opts.keyframes.all_frames = true;
    const io::FramesIndex index = IngestFrames({dir / "flight.mp4"}, io_opts);
    ASSERT_EQ(index.frames.size(), 12u) << gps9;
    for (const auto& f : index.frames) {
      ASSERT_TRUE(f.telemetry.has_value()) << f.name;
      EXPECT_EQ(f.telemetry->source, "GPMF");
      const auto& r = result.klv.at(static_cast<size_t>(f.frame_index));
      // One fix per frame at the frame's time: the frame gets its own fix (GPMF stores 1e-7 degrees, 1 mm).
      EXPECT_NEAR(f.telemetry->sensor_latitude.value_or(NAN), r.sensor_latitude, 1.1e-7) << f.name;
      EXPECT_NEAR(f.telemetry->sensor_longitude.value_or(NAN), r.sensor_longitude, 1.1e-7) << f.name;
      EXPECT_NEAR(f.telemetry->sensor_altitude_hae.value_or(NAN), *r.sensor_ellipsoid_height, 2e-3) << f.name;
      // CORI: the truth rotation relative to frame 0 (16-bit components).
      const Eigen::Quaterniond q(
          f.telemetry->camera_orientation_w.value_or(NAN), f.telemetry->camera_orientation_x.value_or(NAN),
          f.telemetry->camera_orientation_y.value_or(NAN), f.telemetry->camera_orientation_z.value_or(NAN));
      const auto& truth = result.truth.images;
      const Eigen::Matrix3d rel =
          truth.at(1).pose.R() * truth.at(static_cast<uint32_t>(f.frame_index + 1)).pose.R().transpose();
      EXPECT_LT(Eigen::AngleAxisd(q.toRotationMatrix().transpose() * rel).angle(), 2e-4) << f.name;
    }
    const double rms = PositionRms(index, result, o, 0);
    EXPECT_GT(rms, 0.8) << gps9;
    EXPECT_LT(rms, 3.5) << gps9;
    // The whole track goes to telemetry.json for georef.
    EXPECT_TRUE(std::filesystem::exists(dir / "ws/frames/telemetry.json"));
  }
}

}  // namespace
}  // namespace fmv3d::ingest
