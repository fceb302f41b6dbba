#include "fmv3d/synth/telemetry.h"

#include <fmt/format.h>

#include <cmath>
#include <ctime>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/wgs84.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/photo_telemetry.h"

namespace fmv3d::synth {
namespace {

constexpr double kDeg = M_PI / 180;

// Same portable normal as the flight's (std::normal_distribution differs between standard libraries).
struct Normal {
  std::mt19937_64 rng;
  explicit Normal(uint64_t seed) : rng(seed * 0xD1B54A32D192ED03ull + 0x2545F4914F6CDD1Dull) {}
  double operator()() {
    const double u1 = (static_cast<double>(rng() >> 11) + 0.5) / 9007199254740992.0;
    const double u2 = static_cast<double>(rng() >> 11) / 9007199254740992.0;
    return std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
  }
};

}  // namespace

Eigen::Vector3d GeodeticToEcef(const GeoPoint& p) { return geometry::wgs84::GeodeticToEcef(p.lat, p.lon, p.alt); }

GeoPoint EcefToGeodetic(const Eigen::Vector3d& x) {
  const Eigen::Vector3d g = geometry::wgs84::EcefToGeodetic(x);
  return {g.x(), g.y(), g.z()};
}

GeoPoint EnuToGeodetic(const Eigen::Vector3d& enu, const GeoPoint& origin) {
  return EcefToGeodetic(GeodeticToEcef(origin) +
                        geometry::wgs84::EnuFromEcef(origin.lat, origin.lon).transpose() * enu);
}

Eigen::Vector3d GeodeticToEnu(const GeoPoint& p, const GeoPoint& origin) {
  return geometry::wgs84::EnuFromEcef(origin.lat, origin.lon) * (GeodeticToEcef(p) - GeodeticToEcef(origin));
}

void KlvTelemetryOptions::Check() const {
  if (!(std::abs(origin.lat) <= 85))
    throw Error(fmt::format("synth: geo origin latitude {} must be in [-85, 85]", origin.lat));
  if (!(std::abs(origin.lon) <= 180))
    throw Error(fmt::format("synth: geo origin longitude {} must be in [-180, 180]", origin.lon));
  if (!(origin.alt >= -400 && origin.alt <= 9000))
    throw Error(fmt::format("synth: geo origin altitude {} must be in [-400, 9000] m", origin.alt));
  if (!(gps_noise >= 0 && gps_noise <= 1000)) throw Error("synth: --gps-noise must be in [0, 1000] metres");
  if (!(attitude_noise >= 0 && attitude_noise <= 30)) throw Error("synth: --attitude-noise must be in [0, 30] degrees");
  if (!(fps > 0)) throw Error("synth: fps must be positive");
  if (!(std::abs(geoid_undulation) < 200)) throw Error("synth: geoid undulation must be within ±200 m");
}

std::vector<telemetry::klv::St0601Record> MakeKlvTelemetry(const std::vector<core::Pose>& poses,
                                                           const core::Camera& camera, double ground_z,
                                                           const KlvTelemetryOptions& o) {
  o.Check();
  Normal normal(o.seed);
  std::vector<telemetry::klv::St0601Record> out;
  const size_t n = poses.size();
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Vector3d c = poses[k].Centre();
    const Eigen::Matrix3d cam_to_enu = poses[k].R().transpose();
    // Platform heading: horizontal direction of flight (central difference), else the horizontal view direction.
    Eigen::Vector3d v = poses[std::min(k + 1, n - 1)].Centre() - poses[k > 0 ? k - 1 : 0].Centre();
    v.z() = 0;
    if (v.norm() < 1e-6) v = Eigen::Vector3d(cam_to_enu(0, 2), cam_to_enu(1, 2), 0);
    if (v.norm() < 1e-6) v = Eigen::Vector3d::UnitY();
    const double heading = std::atan2(v.x(), v.y()) / kDeg;  // clockwise from north
    telemetry::St0601Attitude a = telemetry::St0601FromCameraToEnu(cam_to_enu, heading, 0, 0);
    // The stated platform attitude is noisy; the sensor angles stay as measured against the true platform.
    a.platform_heading += o.attitude_noise * normal();
    a.platform_pitch += o.attitude_noise * normal();
    a.platform_roll += o.attitude_noise * normal();
    const Eigen::Vector3d noisy = c + o.gps_noise * Eigen::Vector3d(normal(), normal(), normal());
    const GeoPoint g = EnuToGeodetic(noisy, o.origin);

    telemetry::klv::St0601Record r;
    r.unix_time_us = o.start_unix_us + static_cast<uint64_t>(std::llround(1e6 * k / o.fps));
    r.sensor_latitude = g.lat;
    r.sensor_longitude = g.lon;
    r.sensor_true_altitude = g.alt - o.geoid_undulation;
    r.sensor_ellipsoid_height = g.alt;
    r.platform_heading = a.platform_heading;
    r.platform_pitch = a.platform_pitch;
    r.platform_roll = a.platform_roll;
    r.sensor_relative_azimuth = a.sensor_relative_azimuth;
    r.sensor_relative_elevation = a.sensor_relative_elevation;
    r.sensor_relative_roll = a.sensor_relative_roll;
    r.horizontal_fov = 2 * std::atan(0.5 * camera.width / camera.fx()) / kDeg;
    r.vertical_fov = 2 * std::atan(0.5 * camera.height / camera.fy()) / kDeg;
    // Frame centre from the true pose: where the optical axis meets the ground plane.
    const Eigen::Vector3d d = cam_to_enu.col(2);
    if (d.z() < -1e-6 && c.z() > ground_z) {
      const double s = (ground_z - c.z()) / d.z();
      const GeoPoint fc = EnuToGeodetic(c + s * d, o.origin);
      r.slant_range = s;
      r.frame_center_latitude = fc.lat;
      r.frame_center_longitude = fc.lon;
      r.frame_center_elevation = fc.alt - o.geoid_undulation;
      r.frame_center_hae = fc.alt;
    }
    out.push_back(r);
  }
  return out;
}

PhotoMetadata MakePhotoMetadata(const telemetry::klv::St0601Record& r, const core::Camera& camera,
                                const KlvTelemetryOptions& o) {
  PhotoMetadata m;
  io::ExifInfo& e = m.exif;
  e.make = "fmv3d";
  e.model = "synth";
  // What a survey camera writes: the lens focal in mm, its 35 mm equivalent (whole mm) and the focal-plane resolution
  // of its sensor, here a 1-inch type 13.2 mm wide (a DJI Phantom 4 Pro's), so the focal in pixels is exact.
  constexpr double kSensorWidthMm = 13.2;
  e.focal_mm = camera.fx() * kSensorWidthMm / camera.width;
  e.focal_35mm = std::round(camera.fx() * std::hypot(36.0, 24.0) / std::hypot(camera.width, camera.height));
  e.focal_plane_x_res = camera.width / kSensorWidthMm;
  e.pixel_width = camera.width;
  const double t = r.unix_time_us * 1e-6;
  const std::time_t secs = static_cast<std::time_t>(t);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  e.datetime_original = fmt::format("{:04d}:{:02d}:{:02d} {:02d}:{:02d}:{:02d}", tm.tm_year + 1900, tm.tm_mon + 1,
                                    tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec);
  e.gps.latitude = r.sensor_latitude;
  e.gps.longitude = r.sensor_longitude;
  e.gps.altitude = r.sensor_true_altitude;
  e.gps.dop = 1.0;
  if (o.gps_noise > 0) e.gps.horizontal_error = o.gps_noise;
  e.gps.status = 'A';
  e.gps.measure_mode = '3';
  e.gps.map_datum = "WGS-84";
  e.gps.utc_seconds = t;
  telemetry::St0601Attitude a;
  a.platform_heading = r.platform_heading;
  a.platform_pitch = r.platform_pitch;
  a.platform_roll = r.platform_roll;
  a.sensor_relative_azimuth = r.sensor_relative_azimuth;
  a.sensor_relative_elevation = r.sensor_relative_elevation;
  a.sensor_relative_roll = r.sensor_relative_roll;
  const Eigen::Vector3d gimbal = telemetry::GimbalFromCameraToEnu(telemetry::CameraToEnuFromSt0601(a));
  telemetry::DjiXmp x;
  x.gimbal_yaw = gimbal[0];
  x.gimbal_pitch = gimbal[1];
  x.gimbal_roll = gimbal[2];
  x.flight_yaw = r.platform_heading > 180 ? r.platform_heading - 360 : r.platform_heading;
  x.flight_pitch = r.platform_pitch;
  x.flight_roll = r.platform_roll;
  x.absolute_altitude = r.sensor_true_altitude;
  if (r.sensor_ellipsoid_height) x.relative_altitude = *r.sensor_ellipsoid_height - o.origin.alt;
  m.xmp = telemetry::EncodeDjiXmp(x);
  return m;
}

telemetry::gpmf::PayloadContent MakeGpmfPayload(const std::vector<telemetry::klv::St0601Record>& records,
                                                const std::vector<core::Pose>& poses, size_t first, size_t last,
                                                double fps, bool gps9) {
  if (first >= last || last > records.size() || records.size() != poses.size())
    throw Error("synth: GPMF payload frames out of range");
  telemetry::gpmf::PayloadContent c;
  c.gps9 = gps9;
  const Eigen::Matrix3d r0 = poses[0].R();
  for (size_t k = first; k < last; ++k) {
    const auto& r = records[k];
    telemetry::gpmf::GpsFix f;
    f.latitude = r.sensor_latitude;
    f.longitude = r.sensor_longitude;
    f.altitude = r.sensor_ellipsoid_height.value_or(r.sensor_true_altitude);
    const Eigen::Vector3d v =
        (poses[std::min(k + 1, poses.size() - 1)].Centre() - poses[k > 0 ? k - 1 : 0].Centre()) * fps /
        std::max<double>(1.0, static_cast<double>(std::min(k + 1, poses.size() - 1) - (k > 0 ? k - 1 : 0)));
    f.speed_2d = v.head<2>().norm();
    f.speed_3d = v.norm();
    f.unix_seconds = r.unix_time_us * 1e-6;
    c.gps.push_back(f);
    const Eigen::Quaterniond q(r0 * poses[k].R().transpose());
    c.orientation.push_back({q.w(), q.x(), q.y(), q.z()});
  }
  return c;
}

}  // namespace fmv3d::synth
