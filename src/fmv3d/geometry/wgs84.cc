#include "fmv3d/geometry/wgs84.h"

#include <cmath>

namespace fmv3d::geometry::wgs84 {
namespace {

constexpr double kE2 = kFlattening * (2 - kFlattening);  // first eccentricity squared
constexpr double kDeg = 3.14159265358979323846 / 180;

double PrimeVerticalRadius(double sin_lat) { return kSemiMajorAxis / std::sqrt(1 - kE2 * sin_lat * sin_lat); }

}  // namespace

Eigen::Vector3d GeodeticToEcef(double lat_deg, double lon_deg, double height) {
  const double sl = std::sin(lat_deg * kDeg), cl = std::cos(lat_deg * kDeg);
  const double n = PrimeVerticalRadius(sl);
  return {(n + height) * cl * std::cos(lon_deg * kDeg), (n + height) * cl * std::sin(lon_deg * kDeg),
          (n * (1 - kE2) + height) * sl};
}

Eigen::Vector3d EcefToGeodetic(const Eigen::Vector3d& x) {
  // Fixed-point iteration on the latitude from the spherical start: the error shrinks by about e² (0.0067) per
  // step, so ten steps reach machine precision. The height p·cos φ + z·sin φ − a²/N holds at the poles too.
  const double p = std::hypot(x.x(), x.y());
  const auto height = [&](double lat) {
    const double n = PrimeVerticalRadius(std::sin(lat));
    return p * std::cos(lat) + x.z() * std::sin(lat) - kSemiMajorAxis * kSemiMajorAxis / n;
  };
  double lat = std::atan2(x.z(), p * (1 - kE2));
  for (int i = 0; i < 10; ++i) {
    const double n = PrimeVerticalRadius(std::sin(lat));
    lat = std::atan2(x.z(), p * (1 - kE2 * n / (n + height(lat))));
  }
  return {lat / kDeg, std::atan2(x.y(), x.x()) / kDeg, height(lat)};
}

Eigen::Matrix3d EnuFromEcef(double lat_deg, double lon_deg) {
  const double sl = std::sin(lat_deg * kDeg), cl = std::cos(lat_deg * kDeg);
  const double so = std::sin(lon_deg * kDeg), co = std::cos(lon_deg * kDeg);
  Eigen::Matrix3d m;
  m << -so, co, 0, -sl * co, -sl * so, cl, cl * co, cl * so, sl;
  return m;
}

}  // namespace fmv3d::geometry::wgs84
