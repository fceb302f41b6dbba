#include "fmv3d/features/spatial_pairs.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>

namespace fmv3d::features {

namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr double kEarthRadius = 6378137.0;
// Views closer to the horizon than this have no bounded footprint; they are treated as this oblique (the
// footprint is then large, so such frames pair generously rather than not at all).
constexpr double kMinDepressionDeg = 10.0;

using Sample = core::TelemetrySample;

// A field of a frame's telemetry when the frame has one and the value is finite.
std::optional<double> Field(const std::optional<Sample>& t, std::optional<double> Sample::*field) {
  if (!t) return std::nullopt;
  const std::optional<double>& v = (*t).*field;
  return v && std::isfinite(*v) ? v : std::nullopt;
}

struct LocalFrame {  // equirectangular east-north metres about an origin: exact enough for footprint overlap
  double lat0 = 0, lon0 = 0, cos_lat0 = 1;
  Eigen::Vector2d ToLocal(double lat, double lon) const {
    double dlon = lon - lon0;
    if (dlon > 180) dlon -= 360;
    if (dlon < -180) dlon += 360;
    return {kEarthRadius * dlon * kDeg * cos_lat0, kEarthRadius * (lat - lat0) * kDeg};
  }
};

}  // namespace

std::vector<Footprint> FootprintsFromTelemetry(const io::FramesIndex& index) {
  std::vector<Footprint> out(index.frames.size());
  std::optional<LocalFrame> frame;
  for (size_t i = 0; i < index.frames.size(); ++i) {
    const auto& t = index.frames[i].telemetry;
    Footprint& fp = out[i];
    const auto lat = Field(t, &Sample::sensor_latitude), lon = Field(t, &Sample::sensor_longitude);
    if (!lat || !lon) {
      fp.why_invalid = !t ? "no telemetry" : "no sensor latitude/longitude";
      continue;
    }
    // Height above the ground: altitude minus the ground's (frame centre) elevation in the same datum; a
    // relative altitude (DJI: above the take-off point) is taken as height above flat ground.
    std::optional<double> height;
    if (auto a = Field(t, &Sample::sensor_altitude_hae); a && Field(t, &Sample::frame_center_hae))
      height = *a - *Field(t, &Sample::frame_center_hae);
    else if (auto m = Field(t, &Sample::sensor_altitude_msl); m && Field(t, &Sample::frame_center_elevation))
      height = *m - *Field(t, &Sample::frame_center_elevation);
    else if (auto r = Field(t, &Sample::sensor_relative_altitude))
      height = *r;
    else if (auto m2 = Field(t, &Sample::sensor_altitude_msl))
      height = *m2;  // no ground elevation: assume ground near sea level (the footprint is then an upper bound)
    else if (auto h2 = Field(t, &Sample::sensor_altitude_hae))
      height = *h2;
    if (!height || !(*height > 0)) {
      fp.why_invalid = "no usable altitude above the ground";
      continue;
    }
    if (!frame) frame = LocalFrame{*lat, *lon, std::cos(*lat * kDeg)};
    const Eigen::Vector2d sensor = frame->ToLocal(*lat, *lon);

    // Field of view: telemetry, else the camera prior.
    const io::CameraPrior* cam = index.FindCamera(index.frames[i].camera_id);
    double hfov = 0, vfov = 0;
    if (cam && cam->camera.f > 0) {
      hfov = 2 * std::atan(0.5 * cam->camera.width / cam->camera.fx());
      vfov = 2 * std::atan(0.5 * cam->camera.height / cam->camera.fy());
    }
    if (auto h = Field(t, &Sample::horizontal_fov); h && *h > 0 && *h < 180) {
      const double aspect = (hfov > 0 && vfov > 0) ? std::tan(vfov / 2) / std::tan(hfov / 2) : 0.75;
      hfov = *h * kDeg;
      vfov = 2 * std::atan(aspect * std::tan(hfov / 2));
    }
    if (auto v = Field(t, &Sample::vertical_fov); v && *v > 0 && *v < 180) vfov = *v * kDeg;
    if (!(hfov > 0) || !(vfov > 0)) {
      fp.why_invalid = "no field of view (telemetry or camera prior)";
      continue;
    }

    // Pointing: where the optical axis meets the ground and how oblique it is.
    double depression = 90, range = *height;
    const auto fc_lat = Field(t, &Sample::frame_center_latitude), fc_lon = Field(t, &Sample::frame_center_longitude);
    if (fc_lat && fc_lon) {
      fp.centre = frame->ToLocal(*fc_lat, *fc_lon);
      const double ground = (fp.centre - sensor).norm();
      depression = std::atan2(*height, ground) / kDeg;
      range = std::hypot(*height, ground);
      if (auto s = Field(t, &Sample::slant_range); s && *s > 0) range = *s;
    } else {
      std::optional<double> azimuth, elevation;
      if (auto y = Field(t, &Sample::gimbal_yaw)) {
        azimuth = y;
        elevation = Field(t, &Sample::gimbal_pitch);
      } else {
        if (auto n = Field(t, &Sample::sensor_angle_to_north))
          azimuth = n;
        else if (auto h = Field(t, &Sample::platform_heading))
          azimuth = *h + Field(t, &Sample::sensor_relative_azimuth).value_or(0);
        if (auto e = Field(t, &Sample::sensor_relative_elevation))
          elevation = *e + Field(t, &Sample::platform_pitch).value_or(0);
      }
      if (elevation) depression = std::clamp(-*elevation, kMinDepressionDeg, 90.0);
      depression = std::max(depression, kMinDepressionDeg);
      range = *height / std::sin(depression * kDeg);
      const double ground = *height / std::tan(depression * kDeg);
      const double az = azimuth.value_or(0) * kDeg;  // clockwise from north
      fp.centre = sensor + ground * Eigen::Vector2d(std::sin(az), std::cos(az));
    }
    depression = std::max(depression, kMinDepressionDeg);
    const double across = range * std::tan(hfov / 2);
    const double along = range * std::tan(vfov / 2) / std::sin(depression * kDeg);
    fp.radius = std::max(across, along);
    fp.valid = std::isfinite(fp.radius) && fp.radius > 0 && fp.centre.allFinite();
    if (!fp.valid) fp.why_invalid = "degenerate footprint";
  }
  return out;
}

std::vector<ImagePair> SpatialPairs(const std::vector<Footprint>& fps, double overlap_factor, int max_neighbours) {
  std::set<ImagePair> s;
  const size_t n = fps.size();
  for (size_t i = 0; i < n; ++i) {
    if (!fps[i].valid) continue;
    std::vector<std::pair<double, uint32_t>> near;
    for (size_t j = 0; j < n; ++j) {
      if (j == i || !fps[j].valid) continue;
      const double d = (fps[i].centre - fps[j].centre).norm();
      if (d < overlap_factor * (fps[i].radius + fps[j].radius)) near.emplace_back(d, static_cast<uint32_t>(j));
    }
    const size_t take = std::min<size_t>(near.size(), static_cast<size_t>(std::max(0, max_neighbours)));
    std::partial_sort(near.begin(), near.begin() + take, near.end());
    for (size_t k = 0; k < take; ++k) {
      const uint32_t a = static_cast<uint32_t>(i), b = near[k].second;
      s.emplace(std::min(a, b), std::max(a, b));
    }
  }
  return {s.begin(), s.end()};
}

bool PreferSpatialPairs(const io::FramesIndex& index, const std::vector<Footprint>& footprints,
                        const PairOptions& options) {
  const size_t n = index.frames.size();
  if (n <= static_cast<size_t>(options.auto_exhaustive_max_images) || footprints.size() != n) return false;
  std::set<std::string> sources;
  for (const auto& f : index.frames)
    if (f.source.empty() || !sources.insert(f.source).second) return false;
  return std::all_of(footprints.begin(), footprints.end(), [](const Footprint& f) { return f.valid; });
}

}  // namespace fmv3d::features
