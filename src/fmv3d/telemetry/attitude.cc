#include "fmv3d/telemetry/attitude.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace fmv3d::telemetry {
namespace {

constexpr double kDeg = M_PI / 180;

Eigen::Matrix3d Rx(double a) { return Eigen::AngleAxisd(a * kDeg, Eigen::Vector3d::UnitX()).toRotationMatrix(); }
Eigen::Matrix3d Ry(double a) { return Eigen::AngleAxisd(a * kDeg, Eigen::Vector3d::UnitY()).toRotationMatrix(); }
Eigen::Matrix3d Rz(double a) { return Eigen::AngleAxisd(a * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

// NED vectors → ENU vectors (a swap of the first two axes and a flip of the third).
Eigen::Matrix3d EnuFromNed() {
  Eigen::Matrix3d m;
  m << 0, 1, 0, 1, 0, 0, 0, 0, -1;
  return m;
}
// Camera (x right, y down, z forward) vectors → sensor (x line of sight, y right, z down) vectors.
Eigen::Matrix3d SensorFromCamera() {
  Eigen::Matrix3d m;
  m << 0, 0, 1, 1, 0, 0, 0, 1, 0;
  return m;
}

// Z-Y-X angles (degrees) of a rotation m = Rz(z) Ry(y) Rx(x).
Eigen::Vector3d ZyxAngles(const Eigen::Matrix3d& m) {
  return {std::atan2(m(1, 0), m(0, 0)) / kDeg, -std::asin(std::clamp(m(2, 0), -1.0, 1.0)) / kDeg,
          std::atan2(m(2, 1), m(2, 2)) / kDeg};
}

}  // namespace

double Wrap360(double a) {
  a = std::fmod(a, 360.0);
  if (a < 0) a += 360.0;
  return a >= 360.0 ? 0.0 : a;  // fmod of a tiny negative angle rounds up to 360
}

Eigen::Matrix3d CameraToEnuFromSt0601(const St0601Attitude& a) {
  const Eigen::Matrix3d ned_from_body = Rz(a.platform_heading) * Ry(a.platform_pitch) * Rx(a.platform_roll);
  const Eigen::Matrix3d body_from_sensor =
      Rz(a.sensor_relative_azimuth) * Ry(a.sensor_relative_elevation) * Rx(a.sensor_relative_roll);
  return EnuFromNed() * ned_from_body * body_from_sensor * SensorFromCamera();
}

St0601Attitude St0601FromCameraToEnu(const Eigen::Matrix3d& camera_to_enu, double heading, double pitch, double roll) {
  St0601Attitude a;
  a.platform_heading = Wrap360(heading);
  a.platform_pitch = pitch;
  a.platform_roll = roll;
  const Eigen::Matrix3d ned_from_body = Rz(heading) * Ry(pitch) * Rx(roll);
  // body_from_sensor = Rz(az) Ry(el) Rx(roll): read the Z-Y-X angles off its entries.
  const Eigen::Vector3d zyx =
      ZyxAngles(ned_from_body.transpose() * EnuFromNed().transpose() * camera_to_enu * SensorFromCamera().transpose());
  a.sensor_relative_azimuth = Wrap360(zyx[0]);
  a.sensor_relative_elevation = zyx[1];
  a.sensor_relative_roll = Wrap360(zyx[2]);
  return a;
}

Eigen::Matrix3d CameraToEnuFromGimbal(double yaw, double pitch, double roll) {
  St0601Attitude a;
  a.platform_heading = yaw;
  a.platform_pitch = pitch;
  a.platform_roll = roll;
  return CameraToEnuFromSt0601(a);
}

Eigen::Vector3d GimbalFromCameraToEnu(const Eigen::Matrix3d& camera_to_enu) {
  const Eigen::Vector3d zyx = ZyxAngles(EnuFromNed().transpose() * camera_to_enu * SensorFromCamera().transpose());
  return zyx;  // atan2 already gives (−180, 180]
}

}  // namespace fmv3d::telemetry
