#include "fmv3d/geo/geodesy.h"

#include <fmt/format.h>
#include <ogr_spatialref.h>
#include <proj.h>

#include <Eigen/Core>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/wgs84.h"

namespace fmv3d::geo {

std::string UtmZone::Name() const { return fmt::format("WGS 84 / UTM zone {}{}", zone, north ? 'N' : 'S'); }

UtmZone UtmZoneOf(double lat, double lon) {
  if (!(std::abs(lat) <= 84.5) || !(std::abs(lon) <= 180))
    throw Error(fmt::format("UTM: latitude {} / longitude {} is outside UTM's coverage (|lat| <= 84)", lat, lon));
  int zone = static_cast<int>(std::floor((lon + 180) / 6)) + 1;
  if (zone > 60) zone = 60;
  if (lat >= 56 && lat < 64 && lon >= 3 && lon < 12) zone = 32;  // Norway
  if (lat >= 72) {                                               // Svalbard
    if (lon >= 0 && lon < 9)
      zone = 31;
    else if (lon >= 9 && lon < 21)
      zone = 33;
    else if (lon >= 21 && lon < 33)
      zone = 35;
    else if (lon >= 33 && lon < 42)
      zone = 37;
  }
  return {zone, lat >= 0};
}

std::optional<double> GeoidUndulation(double lat, double lon) {
  PJ_CONTEXT* ctx = proj_context_create();
  proj_log_level(ctx, PJ_LOG_NONE);
  // vgridshift with multiplier +1 adds the grid value to z: from z = 0 it gives N.
  PJ* p = proj_create(ctx,
                      "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
                      "+step +proj=vgridshift +grids=egm96_15.gtx +multiplier=1");
  std::optional<double> n;
  if (p) {
    const PJ_COORD out = proj_trans(p, PJ_FWD, proj_coord(lon, lat, 0, 0));
    if (std::isfinite(out.xyz.z) && out.xyz.z != HUGE_VAL && std::abs(out.xyz.z) < 200) n = out.xyz.z;
    proj_destroy(p);
  }
  proj_context_destroy(ctx);
  return n;
}

// ENU ↔ WGS84 is computed here rather than through PROJ's cart + topocentric pipeline: PROJ 9.1's inverse of that
// pipeline reads an uninitialised stack value (valgrind), which made the georeference of one workspace differ in
// its last digits from run to run. The math is the same (EnuPipeline() names the equivalent PROJ pipeline; the
// unit tests hold the two within micrometres). UTM stays with PROJ.
struct LocalFrame::Impl {
  PJ_CONTEXT* ctx = nullptr;
  PJ* utm = nullptr;  // forward: (lon, lat, h) degrees → (E, N, h)
  std::string enu_def, utm_def;
  Eigen::Vector3d origin_ecef;
  Eigen::Matrix3d ecef_to_enu;  // rows: east, north, up at the origin
  ~Impl() {
    if (utm) proj_destroy(utm);
    if (ctx) proj_context_destroy(ctx);
  }
  PJ* Create(const std::string& def) {
    PJ* p = proj_create(ctx, def.c_str());
    if (!p)
      throw Error("PROJ: cannot create '" + def + "': " + proj_context_errno_string(ctx, proj_context_errno(ctx)));
    return p;
  }
  PJ_COORD Trans(PJ* p, PJ_DIRECTION dir, double a, double b, double c) const {
    PJ_COORD in = proj_coord(a, b, c, 0);
    PJ_COORD out = proj_trans(p, dir, in);
    if (!std::isfinite(out.xyz.x) || !std::isfinite(out.xyz.y) || !std::isfinite(out.xyz.z) || out.xyz.x == HUGE_VAL)
      throw Error(fmt::format("PROJ: cannot transform ({}, {}, {})", a, b, c));
    return out;
  }
};

LocalFrame::LocalFrame(const GeoPoint& origin) : LocalFrame(origin, UtmZoneOf(origin.lat, origin.lon)) {}

LocalFrame::LocalFrame(const GeoPoint& origin, const UtmZone& zone)
    : origin_(origin), zone_(zone), impl_(std::make_unique<Impl>()) {
  if (!(std::abs(origin.lat) <= 90 && std::abs(origin.lon) <= 180 && std::isfinite(origin.alt)))
    throw Error(fmt::format("geo: bad origin lat {} lon {} alt {}", origin.lat, origin.lon, origin.alt));
  impl_->ctx = proj_context_create();
  if (!impl_->ctx) throw Error("PROJ: cannot create a context");
  proj_log_level(impl_->ctx, PJ_LOG_NONE);
  impl_->enu_def = fmt::format(
      "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=cart +ellps=WGS84 "
      "+step +proj=topocentric +ellps=WGS84 +lat_0={:.12f} +lon_0={:.12f} +h_0={:.6f}",
      origin.lat, origin.lon, origin.alt);
  impl_->utm_def = fmt::format(
      "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step +proj=utm +zone={}{} +ellps=WGS84",
      zone.zone, zone.north ? "" : " +south");
  impl_->utm = impl_->Create(impl_->utm_def);
  impl_->origin_ecef = geometry::wgs84::GeodeticToEcef(origin.lat, origin.lon, origin.alt);
  impl_->ecef_to_enu = geometry::wgs84::EnuFromEcef(origin.lat, origin.lon);
}

LocalFrame::~LocalFrame() = default;

Eigen::Vector3d LocalFrame::ToEnu(const GeoPoint& p) const {
  if (!(std::isfinite(p.lat) && std::isfinite(p.lon) && std::isfinite(p.alt)))
    throw Error(fmt::format("geo: cannot transform ({}, {}, {})", p.lon, p.lat, p.alt));
  return impl_->ecef_to_enu * (geometry::wgs84::GeodeticToEcef(p.lat, p.lon, p.alt) - impl_->origin_ecef);
}

GeoPoint LocalFrame::ToGeodetic(const Eigen::Vector3d& enu) const {
  if (!enu.allFinite()) throw Error(fmt::format("geo: cannot transform ({}, {}, {})", enu.x(), enu.y(), enu.z()));
  const Eigen::Vector3d g = geometry::wgs84::EcefToGeodetic(impl_->origin_ecef + impl_->ecef_to_enu.transpose() * enu);
  return {g.x(), g.y(), g.z()};
}

Eigen::Vector3d LocalFrame::GeodeticToUtm(const GeoPoint& p) const {
  const PJ_COORD c = impl_->Trans(impl_->utm, PJ_FWD, p.lon, p.lat, p.alt);
  return {c.xyz.x, c.xyz.y, c.xyz.z};
}

GeoPoint LocalFrame::UtmToGeodetic(const Eigen::Vector3d& u) const {
  const PJ_COORD c = impl_->Trans(impl_->utm, PJ_INV, u.x(), u.y(), u.z());
  return {c.xyz.y, c.xyz.x, c.xyz.z};
}

Eigen::Vector3d LocalFrame::EnuToUtm(const Eigen::Vector3d& enu) const { return GeodeticToUtm(ToGeodetic(enu)); }

void LocalFrame::EnuToUtm(std::vector<Eigen::Vector3d>* points) const {
  if (points->empty()) return;
  for (auto& p : *points) {
    const GeoPoint g = ToGeodetic(p);
    p = {g.lon, g.lat, g.alt};
  }
  const size_t n = points->size(), stride = sizeof(Eigen::Vector3d);
  double* base = points->front().data();
  // Eigen::Vector3d is three packed doubles: x, y, z at stride 24 bytes.
  proj_trans_generic(impl_->utm, PJ_FWD, base, stride, n, base + 1, stride, n, base + 2, stride, n, nullptr, 0, 0);
  for (const auto& p : *points)
    if (!p.allFinite() || p.x() == HUGE_VAL) throw Error("PROJ: a point could not be transformed to UTM");
}

std::string LocalFrame::EnuPipeline() const { return impl_->enu_def; }
std::string LocalFrame::UtmPipeline() const { return impl_->utm_def; }

std::string UtmWkt(const UtmZone& zone, bool wkt1) {
  OGRSpatialReference srs;
  if (srs.importFromEPSG(zone.Epsg()) != OGRERR_NONE)
    throw Error(fmt::format("GDAL: cannot build the CRS EPSG:{}", zone.Epsg()));
  char* wkt = nullptr;
  const char* const opts_wkt2[] = {"FORMAT=WKT2_2019", nullptr};
  const char* const opts_wkt1[] = {"FORMAT=WKT1", nullptr};
  if (srs.exportToWkt(&wkt, wkt1 ? opts_wkt1 : opts_wkt2) != OGRERR_NONE || !wkt)
    throw Error(fmt::format("GDAL: cannot write the WKT of EPSG:{}", zone.Epsg()));
  std::string s(wkt);
  CPLFree(wkt);
  return s;
}

}  // namespace fmv3d::geo
