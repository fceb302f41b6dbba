#include "fmv3d/server/geo_json.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/raster.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

namespace {
nlohmann::json Optional(const fs::path& ws, const char* rel) {
  std::error_code ec;
  return fs::is_regular_file(ws / rel, ec) ? nlohmann::json(rel) : nlohmann::json();
}

// Bilinear height at fractional (col, row) of cell centres; nullopt outside or next to a no-data cell.
std::optional<double> Sample(const cv::Mat& h, double col, double row) {
  const double x = col - 0.5, y = row - 0.5;
  const int c0 = static_cast<int>(std::floor(x)), r0 = static_cast<int>(std::floor(y));
  if (c0 < 0 || r0 < 0 || c0 + 1 >= h.cols || r0 + 1 >= h.rows) {
    const int c = static_cast<int>(std::floor(col)), r = static_cast<int>(std::floor(row));
    if (c < 0 || r < 0 || c >= h.cols || r >= h.rows) return std::nullopt;
    const float v = h.at<float>(r, c);
    return (v == geo::kNoData || std::isnan(v)) ? std::nullopt : std::optional<double>(v);
  }
  const double fx = x - c0, fy = y - r0;
  double sum = 0;
  for (int dr = 0; dr < 2; ++dr)
    for (int dc = 0; dc < 2; ++dc) {
      const float v = h.at<float>(r0 + dr, c0 + dc);
      if (v == geo::kNoData || std::isnan(v)) return std::nullopt;
      sum += v * (dr ? fy : 1 - fy) * (dc ? fx : 1 - fx);
    }
  return sum;
}

std::optional<double> MedianHeight(const cv::Mat& h) {
  std::vector<float> v;
  for (int r = 0; r < h.rows; r += std::max(1, h.rows / 200))
    for (int c = 0; c < h.cols; c += std::max(1, h.cols / 200)) {
      const float x = h.at<float>(r, c);
      if (x != geo::kNoData && !std::isnan(x)) v.push_back(x);
    }
  if (v.empty()) return std::nullopt;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

Eigen::Matrix4d MatrixFrom(const nlohmann::json& m) {
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = m.at(r).at(c).get<double>();
  return M;
}
}  // namespace

nlohmann::json GeoJson(const fs::path& ws) {
  const fs::path georef_path = ws / "geo" / "georef.json";
  std::error_code ec;
  if (!fs::is_regular_file(georef_path, ec)) return nullptr;
  const nlohmann::json g = core::ReadJson(georef_path);
  geo::GeoPoint origin;
  geo::UtmZone zone;
  Eigen::Matrix4d sim;
  try {
    origin = {g.at("origin").at("lat").get<double>(), g.at("origin").at("lon").get<double>(),
              g.at("origin").at("alt").get<double>()};
    zone.zone = g.at("utm").at("zone").get<int>();
    zone.north = g.at("utm").at("north").get<bool>();
    sim = MatrixFrom(g.at("similarity").at("matrix"));
  } catch (const nlohmann::json::exception& e) {
    throw Error(georef_path.string() + ": malformed (" + e.what() + ")");
  }
  const geo::LocalFrame frame(origin, zone);
  nlohmann::json out = {{"epsg", zone.Epsg()},
                        {"origin", {{"lat", origin.lat}, {"lon", origin.lon}, {"alt", origin.alt}}},
                        {"bounds_wgs84", nullptr},
                        {"ortho", Optional(ws, "geo/ortho.tif")},
                        {"dsm", Optional(ws, "geo/dsm.tif")},
                        {"hillshade", Optional(ws, "geo/hillshade.png")}};
  // Bounds and ground level from the DSM.
  double ground_z = 0;
  bool have_ground = false;
  if (fs::is_regular_file(ws / "geo" / "dsm.tif", ec)) {
    geo::GridSpec grid;
    const cv::Mat h = geo::ReadHeightGeoTiff(ws / "geo" / "dsm.tif", &grid);
    double w = 180, s = 90, e = -180, n = -90;
    for (double fx : {0.0, 1.0})
      for (double fy : {0.0, 1.0}) {
        const geo::GeoPoint p =
            frame.UtmToGeodetic({grid.min_e + fx * grid.width * grid.gsd, grid.max_n - fy * grid.height * grid.gsd, 0});
        w = std::min(w, p.lon), e = std::max(e, p.lon), s = std::min(s, p.lat), n = std::max(n, p.lat);
      }
    out["bounds_wgs84"] = {w, s, e, n};
    if (const auto median = MedianHeight(h)) {
      const double cx = grid.min_e + 0.5 * grid.width * grid.gsd, cy = grid.max_n - 0.5 * grid.height * grid.gsd;
      ground_z = frame.ToEnu(frame.UtmToGeodetic({cx, cy, *median})).z();
      have_ground = true;
    }
  }
  // Track: the keyframes' telemetry positions.
  nlohmann::json track = nlohmann::json::array();
  try {
    for (const auto& f : io::ReadFramesIndex(core::Workspace(ws).frames_json()).frames) {
      if (!f.telemetry || !f.telemetry->sensor_latitude || !f.telemetry->sensor_longitude) continue;
      const auto& t = *f.telemetry;
      const double alt = t.sensor_altitude_hae.value_or(t.sensor_altitude_msl.value_or(0.0));
      track.push_back({*t.sensor_latitude, *t.sensor_longitude, alt});
    }
  } catch (const std::exception&) {
  }
  out["track"] = track;
  // Footprints: image corners cast onto the plane z = ground_z (ENU) from the georeferenced cameras.
  nlohmann::json footprints = nlohmann::json::array();
  if (fs::is_regular_file(core::Workspace(ws).sparse_dir() / "images.txt", ec)) {
    const core::Reconstruction rec = io::ReadColmapText(core::Workspace(ws).sparse_dir());
    const double scale = sim.block<3, 1>(0, 0).norm();
    const Eigen::Matrix3d Rs = sim.block<3, 3>(0, 0) / scale;
    if (!have_ground && !rec.points.empty()) {
      std::vector<double> z;
      for (const auto& [id, p] : rec.points) z.push_back((sim * p.xyz.homogeneous()).z());
      std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
      ground_z = z[z.size() / 2];
    }
    for (const auto& [id, im] : rec.images) {
      const auto cam = rec.cameras.find(im.camera_id);
      if (cam == rec.cameras.end()) continue;
      const Eigen::Matrix3d R = im.pose.R();
      const Eigen::Vector3d c = (sim * (-R.transpose() * im.pose.t).homogeneous()).head<3>();
      const double height = c.z() - ground_z;
      if (height <= 0) continue;
      nlohmann::json quad = nlohmann::json::array();
      const double W = cam->second.width, H = cam->second.height;
      for (const auto& uv :
           {Eigen::Vector2d(0, 0), Eigen::Vector2d(W, 0), Eigen::Vector2d(W, H), Eigen::Vector2d(0, H)}) {
        const Eigen::Vector3d ray_cam((uv.x() - cam->second.u0) / cam->second.fx(),
                                      (uv.y() - cam->second.v0) / cam->second.fy(), 1.0);
        const Eigen::Vector3d d = Rs * (R.transpose() * ray_cam);
        // Rays at or above the horizon are cut at 10 heights out, so that oblique views still show a footprint.
        double s = d.z() < -1e-6 ? height / -d.z() : 1e300;
        s = std::min(s, 10 * height / std::max(1e-9, std::hypot(d.x(), d.y())));
        const Eigen::Vector3d p = c + s * d;
        const geo::GeoPoint q = frame.ToGeodetic({p.x(), p.y(), ground_z});
        quad.push_back({q.lat, q.lon});
      }
      footprints.push_back(quad);
    }
  }
  out["footprints"] = footprints;
  return out;
}

nlohmann::json ProfileJson(const fs::path& ws, const LatLon& from, const LatLon& to, int n) {
  const fs::path dsm = ws / "geo" / "dsm.tif";
  std::error_code ec;
  if (!fs::is_regular_file(dsm, ec)) throw Error("no geo/dsm.tif in this workspace");
  geo::GridSpec grid;
  const cv::Mat h = geo::ReadHeightGeoTiff(dsm, &grid);
  const geo::LocalFrame frame({from.lat, from.lon, 0}, grid.zone);
  const Eigen::Vector3d a = frame.GeodeticToUtm({from.lat, from.lon, 0});
  const Eigen::Vector3d b = frame.GeodeticToUtm({to.lat, to.lon, 0});
  const double length = (b - a).head<2>().norm();
  nlohmann::json points = nlohmann::json::array();
  for (int i = 0; i < n; ++i) {
    const double f = n > 1 ? static_cast<double>(i) / (n - 1) : 0.0;
    const Eigen::Vector3d p = a + f * (b - a);
    const geo::GeoPoint g = frame.UtmToGeodetic({p.x(), p.y(), 0});
    const auto v = Sample(h, grid.Col(p.x()), grid.Row(p.y()));
    points.push_back({{"lat", g.lat},
                      {"lon", g.lon},
                      {"distance_m", f * length},
                      {"height_m", v ? nlohmann::json(*v) : nlohmann::json()}});
  }
  return {{"points", points}};
}

}  // namespace fmv3d::server
