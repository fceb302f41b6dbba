#include "fmv3d/geo/gcp_list.h"

#include <cpl_error.h>
#include <fmt/format.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <regex>
#include <sstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::geo {
namespace {

std::string Trim(const std::string& s) {
  size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Parses a whole field as a finite double ("12,5", "1e999", "nan" and "3m" are not numbers here).
bool ParseNumber(const std::string& s, double* out) {
  if (s.empty() || s.size() > 64) return false;
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || errno == ERANGE || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

// GDAL reports through CPLError; collect the last message instead of printing it.
class QuietGdal {
 public:
  QuietGdal() {
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
  }
  ~QuietGdal() { CPLPopErrorHandler(); }
  std::string Last() const {
    const char* m = CPLGetLastErrorMsg();
    return m && *m ? m : "not found in PROJ's database";
  }
};

}  // namespace

bool GcpLine::IsCheck() const {
  if (extra.empty()) return false;
  const std::string e = Lower(extra.front());
  return e == "check" || e == "checkpoint";
}

struct GcpCrs::Impl {
  OGRSpatialReference src, wgs84;
  std::unique_ptr<OGRCoordinateTransformation> fwd, inv;
};

GcpCrs::GcpCrs(const std::string& crs_line) : impl_(std::make_unique<Impl>()) {
  const std::string crs = Trim(crs_line);
  static const std::regex kEpsg(R"(EPSG:(\d{1,6})(\+(\d{1,6}))?)", std::regex::icase);
  static const std::regex kOdmUtm(R"(WGS\s?84\s+UTM\s+(\d{1,2})\s*([NS]))", std::regex::icase);
  std::smatch m;
  QuietGdal quiet;
  OGRErr err = OGRERR_FAILURE;
  if (std::regex_match(crs, m, kEpsg)) {
    if (m[2].matched) {
      const std::string user = "EPSG:" + m[1].str() + "+" + m[3].str();
      err = impl_->src.SetFromUserInput(user.c_str());
    } else {
      epsg_ = std::stoi(m[1].str());
      err = impl_->src.importFromEPSG(epsg_);
    }
  } else if (std::regex_match(crs, m, kOdmUtm)) {
    const int zone = std::stoi(m[1].str());
    if (zone < 1 || zone > 60) throw Error(fmt::format("CRS \"{}\": UTM zone {} is not in 1..60", crs, zone));
    epsg_ = (std::toupper(static_cast<unsigned char>(m[2].str()[0])) == 'N' ? 32600 : 32700) + zone;
    err = impl_->src.importFromEPSG(epsg_);
  } else if (crs.rfind("+proj=", 0) == 0) {
    err = impl_->src.importFromProj4(crs.c_str());
  } else {
    throw Error(
        fmt::format("CRS \"{}\" is not one of EPSG:<code>, \"WGS84 UTM <zone><N|S>\" or a PROJ string "
                    "\"+proj=...\"",
                    crs.substr(0, 80)));
  }
  if (err != OGRERR_NONE) throw Error(fmt::format("unknown CRS \"{}\" (GDAL: {})", crs.substr(0, 80), quiet.Last()));
  if (!impl_->src.IsProjected() && !impl_->src.IsGeographic() && !impl_->src.IsCompound())
    throw Error(fmt::format("CRS \"{}\" is neither geographic nor projected (a GCP needs horizontal coordinates)",
                            crs.substr(0, 80)));
  impl_->src.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);  // x = easting / longitude, as ODM
  impl_->wgs84.importFromEPSG(4979);
  impl_->wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  impl_->fwd.reset(OGRCreateCoordinateTransformation(&impl_->src, &impl_->wgs84));
  impl_->inv.reset(OGRCreateCoordinateTransformation(&impl_->wgs84, &impl_->src));
  if (!impl_->fwd || !impl_->inv)
    throw Error(fmt::format("CRS \"{}\": no transformation to WGS84 (GDAL: {})", crs.substr(0, 80), quiet.Last()));
  const char* name = impl_->src.GetName();
  name_ = name ? name : crs;
  vertical_datum_ = "WGS84 ellipsoid";
  if (impl_->src.IsCompound()) {
    const char* v = impl_->src.GetAttrValue("VERT_CS");
    vertical_datum_ = v ? v : "the CRS's vertical datum";
  }
}

GcpCrs::~GcpCrs() = default;

GeoPoint GcpCrs::ToWgs84(const Eigen::Vector3d& geo) const {
  double x = geo.x(), y = geo.y(), z = geo.z();
  QuietGdal quiet;
  if (!impl_->fwd->Transform(1, &x, &y, &z) || !std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
    throw Error(fmt::format("({}, {}, {}) cannot be transformed from {} to WGS84", geo.x(), geo.y(), geo.z(), name_));
  return {y, x, z};
}

Eigen::Vector3d GcpCrs::FromWgs84(const GeoPoint& p) const {
  double x = p.lon, y = p.lat, z = p.alt;
  QuietGdal quiet;
  if (!impl_->inv->Transform(1, &x, &y, &z) || !std::isfinite(x) || !std::isfinite(y))
    throw Error(fmt::format("({}, {}, {}) cannot be transformed from WGS84 to {}", p.lat, p.lon, p.alt, name_));
  return {x, y, z};
}

namespace {
// A coordinate the CRS maps to a real place: PROJ transforms it to finite WGS84 with |lat| ≤ 90°, |lon| ≤ 180°
// (a longitude of 200 or a swapped easting/northing is a typing error, not a position).
bool InWgs84Range(const GcpCrs& crs, const Eigen::Vector3d& geo) {
  try {
    const GeoPoint p = crs.ToWgs84(geo);
    return std::abs(p.lat) <= 90 && std::abs(p.lon) <= 180;
  } catch (const Error&) {
    return false;
  }
}
}  // namespace

GcpList ParseGcpList(const std::string& text, std::vector<std::string>* errors, const std::string& what) {
  GcpList list;
  std::istringstream in(text);
  std::string raw;
  int line_no = 0;
  bool have_crs = false;
  std::unique_ptr<GcpCrs> crs;
  auto fail = [&](const std::string& msg) { errors->push_back(fmt::format("{}:{}: {}", what, line_no, msg)); };
  while (std::getline(in, raw)) {
    ++line_no;
    const std::string line = Trim(raw);
    if (line.empty() || line[0] == '#') continue;
    if (!have_crs) {
      have_crs = true;
      list.crs = line;
      try {
        crs = std::make_unique<GcpCrs>(line);
      } catch (const Error& e) {
        fail(e.what());
      }
      continue;
    }
    std::istringstream fields(line);
    std::vector<std::string> f;
    for (std::string s; fields >> s;) f.push_back(s);
    if (f.size() < 6) {
      fail(fmt::format("expected geo_x geo_y geo_z im_x im_y image_name [gcp_name] [extra ...], got {} field{}",
                       f.size(), f.size() == 1 ? "" : "s"));
      continue;
    }
    GcpLine g;
    g.line = line_no;
    double v[5];
    static const char* kNames[5] = {"geo_x", "geo_y", "geo_z", "im_x", "im_y"};
    bool ok = true;
    for (int k = 0; k < 5; ++k)
      if (!ParseNumber(f[k], &v[k])) {
        fail(fmt::format("{} \"{}\" is not a number", kNames[k], f[k].substr(0, 40)));
        ok = false;
      }
    if (!ok) continue;
    g.geo = {v[0], v[1], v[2]};
    if (crs && !InWgs84Range(*crs, g.geo)) {
      fail(
          fmt::format("({}, {}, {}) is not a place in {} (geo_x is the easting or longitude, geo_y the northing or "
                      "latitude)",
                      f[0].substr(0, 40), f[1].substr(0, 40), f[2].substr(0, 40), crs->name()));
      continue;
    }
    g.im_x = v[3];
    g.im_y = v[4];
    g.image = f[5];
    if (f.size() > 6) g.name = f[6];
    g.extra.assign(f.begin() + std::min<size_t>(7, f.size()), f.end());
    if (g.name.empty() == false && (Lower(g.name) == "check" || Lower(g.name) == "checkpoint") && g.extra.empty()) {
      fail("a check point needs a name before \"check\": ... image_name gcp_name check");
      continue;
    }
    list.lines.push_back(std::move(g));
  }
  if (!have_crs) {
    line_no = std::max(line_no, 1);
    fail("empty file: the first line must name the CRS (e.g. EPSG:4326)");
  }
  // One name, one place, one click per frame.
  std::map<std::string, const GcpLine*> first;
  std::map<std::pair<std::string, std::string>, const GcpLine*> clicked;
  for (const auto& g : list.lines) {
    if (g.name.empty()) continue;
    auto [it, inserted] = first.emplace(g.name, &g);
    line_no = g.line;
    if (!inserted && (it->second->geo - g.geo).cwiseAbs().maxCoeff() > 1e-9 * std::max(1.0, g.geo.norm())) {
      fail(fmt::format("GCP \"{}\" has other coordinates than on line {}", g.name, it->second->line));
      continue;
    }
    if (!inserted && it->second->IsCheck() != g.IsCheck())
      fail(fmt::format("GCP \"{}\" is marked as a check point on one line and not on another (line {})", g.name,
                       it->second->line));
    const auto [c, new_frame] = clicked.emplace(std::make_pair(g.name, g.image), &g);
    if (!new_frame && (c->second->im_x != g.im_x || c->second->im_y != g.im_y))
      fail(fmt::format(
          "GCP \"{}\" is clicked a second time in frame \"{}\" (first on line {}); keep one click per frame", g.name,
          g.image, c->second->line));
  }
  return list;
}

std::string FormatGcpList(const GcpList& list) {
  std::string out = list.crs + "\n";
  for (const auto& g : list.lines) {
    out += fmt::format("{:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {}", g.geo.x(), g.geo.y(), g.geo.z(), g.im_x, g.im_y,
                       g.image);
    if (!g.name.empty()) out += " " + g.name;
    for (const auto& e : g.extra) out += " " + e;
    out += "\n";
  }
  return out;
}

void CheckGcpList(const GcpList& list, const io::FrameTable& frames, std::vector<std::string>* errors,
                  const std::string& what) {
  for (const auto& g : list.lines) {
    const auto it = frames.find(g.image);
    if (it == frames.end()) {
      errors->push_back(fmt::format("{}:{}: frame \"{}\" is not in frames/frames.json", what, g.line, g.image));
      continue;
    }
    if (!(g.im_x >= 0 && g.im_x <= it->second.width && g.im_y >= 0 && g.im_y <= it->second.height))
      errors->push_back(fmt::format("{}:{}: ({:.2f}, {:.2f}) is outside {} ({}x{})", what, g.line, g.im_x, g.im_y,
                                    g.image, it->second.width, it->second.height));
  }
  for (const auto& p : GroupGcps(list))
    if (p.observations.size() < 2)
      errors->push_back(fmt::format("{}:{}: GCP \"{}\" is clicked in {} frame; it needs ≥ 2 to be triangulated", what,
                                    p.first_line, p.name, p.observations.size()));
}

GcpList ReadGcpList(const std::filesystem::path& path, const io::FrameTable* frames) {
  const std::string what = path.string();
  std::vector<std::string> errors;
  GcpList list = ParseGcpList(core::ReadTextFile(path), &errors, what);
  if (errors.empty() && frames) CheckGcpList(list, *frames, &errors, what);
  if (!errors.empty()) throw Error(io::JoinErrors(errors));
  return list;
}

void WriteGcpList(const GcpList& list, const std::filesystem::path& path, const io::FrameTable* frames) {
  const std::string text = FormatGcpList(list);
  std::vector<std::string> errors;
  const GcpList again = ParseGcpList(text, &errors, path.string());
  if (errors.empty() && frames) CheckGcpList(again, *frames, &errors, path.string());
  if (!errors.empty()) throw Error("not saved: " + io::JoinErrors(errors));
  core::EnsureDirectory(path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path());
  core::WriteTextFile(path, text);
}

std::vector<GroundControlPoint> GroupGcps(const GcpList& list) {
  std::vector<GroundControlPoint> points;
  std::map<std::string, size_t> by_key;
  for (const auto& g : list.lines) {
    const std::string key =
        g.name.empty() ? fmt::format("@{:.17g},{:.17g},{:.17g}", g.geo.x(), g.geo.y(), g.geo.z()) : g.name;
    auto [it, inserted] = by_key.emplace(key, points.size());
    if (inserted) {
      GroundControlPoint p;
      p.name = g.name.empty() ? fmt::format("line {}", g.line) : g.name;
      p.check = g.IsCheck();
      p.geo = g.geo;
      p.first_line = g.line;
      points.push_back(std::move(p));
    }
    GroundControlPoint& p = points[it->second];
    const bool seen = std::any_of(p.observations.begin(), p.observations.end(),
                                  [&](const io::ImagePoint& o) { return o.frame == g.image; });
    if (!seen) p.observations.push_back({g.image, g.im_x, g.im_y});
  }
  return points;
}

}  // namespace fmv3d::geo
