// Attitude conventions of the telemetry sources, and their conversion to our camera-to-ENU rotations.
//
// Our cameras are OpenCV-style (x right, y down, z forward); our local frame is East-North-Up.
//
// MISB ST 0601 (§6): the platform's heading/pitch/roll are the yaw-pitch-roll (Z-Y-X) Euler angles of the body
// frame (x forward, y right wing, z down) in local North-East-Down; the sensor's relative azimuth, elevation
// and roll are the Z-Y-X angles of the sensor frame (x along the line of sight, y right, z down) in the body
// frame.
//
// DJI gimbal angles (SRT gb_yaw/gb_pitch/gb_roll, XMP drone-dji:GimbalYaw/Pitch/Roll) are absolute: the same
// Z-Y-X chain applied directly to the sensor frame in NED (yaw from true north, clockwise; pitch from the
// horizon, −90 = nadir; roll about the line of sight), i.e. ST 0601 with a level platform and the gimbal
// angles as the platform's.
#pragma once

#include <Eigen/Core>

namespace fmv3d::telemetry {

// Euler angles (degrees) of ST 0601's platform + sensor chain.
struct St0601Attitude {
  double platform_heading = 0, platform_pitch = 0, platform_roll = 0;
  double sensor_relative_azimuth = 0, sensor_relative_elevation = 0, sensor_relative_roll = 0;
};

// Camera-to-ENU rotation (columns: the camera's x right, y down, z forward in East-North-Up) of a sensor
// with these angles.
Eigen::Matrix3d CameraToEnuFromSt0601(const St0601Attitude& attitude);

// Splits a camera-to-ENU rotation into the sensor's relative angles for a given platform heading/pitch/roll
// (the split is not unique: the platform attitude is a choice, e.g. the direction of flight). Returns the
// attitude with the platform angles as given and the sensor angles that reproduce `camera_to_enu`.
St0601Attitude St0601FromCameraToEnu(const Eigen::Matrix3d& camera_to_enu, double platform_heading,
                                     double platform_pitch, double platform_roll);

// Camera-to-ENU rotation of DJI absolute gimbal angles (degrees, see above).
Eigen::Matrix3d CameraToEnuFromGimbal(double yaw, double pitch, double roll);
// The inverse: DJI gimbal yaw (wrapped to (−180, 180]), pitch and roll of a camera-to-ENU rotation.
Eigen::Vector3d GimbalFromCameraToEnu(const Eigen::Matrix3d& camera_to_enu);

// An angle in degrees wrapped to [0, 360).
double Wrap360(double degrees);

}  // namespace fmv3d::telemetry
