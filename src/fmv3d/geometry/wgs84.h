// The WGS84 ellipsoid: geodetic coordinates (latitude and longitude in degrees, ellipsoidal height in metres) ↔
// Earth-centred Earth-fixed metres, and the local East-North-Up axes. Closed-form and iteration-count fixed, so
// a conversion gives the same bits on every run (shared by the georeference and the synthetic telemetry).
#pragma once

#include <Eigen/Core>

namespace fmv3d::geometry::wgs84 {

constexpr double kSemiMajorAxis = 6378137.0;
constexpr double kFlattening = 1 / 298.257223563;

Eigen::Vector3d GeodeticToEcef(double lat_deg, double lon_deg, double height);
// (latitude°, longitude°, height): to machine precision anywhere outside the Earth's central ~40 km.
Eigen::Vector3d EcefToGeodetic(const Eigen::Vector3d& ecef);
// The rotation whose rows are the local East, North and Up unit vectors in ECEF.
Eigen::Matrix3d EnuFromEcef(double lat_deg, double lon_deg);

}  // namespace fmv3d::geometry::wgs84
