// Coordinate frames of the terrain products, via PROJ: WGS84 geodetic (EPSG:4979: latitude, longitude in
// degrees, height above the ellipsoid in metres), a local East-North-Up (topocentric) frame at an origin, and
// UTM (WGS84 / UTM zone N|S, EPSG:326NN / 327NN; heights stay ellipsoidal).
//
// Heights are passed through unchanged by the UTM projection; whatever vertical datum the input heights use
// (ellipsoidal, or MSL when the telemetry only states MSL) is the datum of every product, and georef.json says
// which.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::geo {

struct GeoPoint {
  double lat = 0, lon = 0, alt = 0;  // degrees, degrees, metres
};

struct UtmZone {
  int zone = 0;  // 1..60
  bool north = true;
  int Epsg() const { return (north ? 32600 : 32700) + zone; }
  std::string Name() const;  // "WGS 84 / UTM zone 18N"
};
// The standard zone of a longitude/latitude (with the Norway / Svalbard exceptions).
UtmZone UtmZoneOf(double lat, double lon);

// EGM96 geoid undulation N (metres: ellipsoidal height = height above mean sea level + N) at a WGS84 point, from
// PROJ's egm96_15.gtx (Debian proj-data, a dependency of libproj); nullopt when the grid is not available.
std::optional<double> GeoidUndulation(double lat, double lon);

// ENU ↔ WGS84 ↔ UTM around one origin. Not thread-safe (one PROJ context per object): give each thread its own.
class LocalFrame {
 public:
  // The UTM zone defaults to the origin's.
  explicit LocalFrame(const GeoPoint& origin);
  LocalFrame(const GeoPoint& origin, const UtmZone& zone);
  ~LocalFrame();
  LocalFrame(const LocalFrame&) = delete;
  LocalFrame& operator=(const LocalFrame&) = delete;

  const GeoPoint& origin() const { return origin_; }
  const UtmZone& utm_zone() const { return zone_; }

  Eigen::Vector3d ToEnu(const GeoPoint& p) const;
  GeoPoint ToGeodetic(const Eigen::Vector3d& enu) const;
  // (easting, northing, height) in the frame's UTM zone.
  Eigen::Vector3d GeodeticToUtm(const GeoPoint& p) const;
  GeoPoint UtmToGeodetic(const Eigen::Vector3d& utm) const;
  Eigen::Vector3d EnuToUtm(const Eigen::Vector3d& enu) const;
  // In place, batched (PROJ's proj_trans_generic): ENU → UTM for many points.
  void EnuToUtm(std::vector<Eigen::Vector3d>* points) const;

  // The PROJ pipelines used, for georef.json: ENU → WGS84 (lon, lat, h) and WGS84 → UTM.
  std::string EnuPipeline() const;
  std::string UtmPipeline() const;

 private:
  struct Impl;
  GeoPoint origin_;
  UtmZone zone_;
  std::unique_ptr<Impl> impl_;
};

// WKT (OGC 2019 / WKT2 or WKT1, via GDAL's OSR) of a UTM zone's compound-free CRS, for GeoTIFF and LAS.
std::string UtmWkt(const UtmZone& zone, bool wkt1 = false);

}  // namespace fmv3d::geo
