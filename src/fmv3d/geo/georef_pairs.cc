#include "fmv3d/geo/georef_pairs.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/geo/trajectory.h"
#include "fmv3d/telemetry/attitude.h"

namespace fmv3d::geo {
namespace {

bool HasPosition(const telemetry::TelemetrySample& s) {
  return s.sensor_latitude && s.sensor_longitude && (s.sensor_altitude_hae || s.sensor_altitude_msl);
}

GeorefPair MakePair(const std::string& name, const Eigen::Vector3d& centre, const Eigen::Quaterniond& rotation,
                    const telemetry::TelemetrySample& s) {
  GeorefPair p;
  p.name = name;
  p.centre = centre;
  p.rotation = rotation;
  p.pos.lat = *s.sensor_latitude;
  p.pos.lon = *s.sensor_longitude;
  p.hae = s.sensor_altitude_hae;
  p.msl = s.sensor_altitude_msl;
  p.attitude = TelemetryAttitude(s);
  if (s.frame_center_latitude && s.frame_center_longitude)
    p.frame_centre = GeoPoint{*s.frame_center_latitude, *s.frame_center_longitude, 0};
  p.frame_centre_hae = s.frame_center_hae;
  p.frame_centre_msl = s.frame_center_elevation;
  p.slant_range = s.slant_range;
  p.time = s.time;
  return p;
}

}  // namespace

const char* VerticalDatumName(VerticalDatum d) { return d == VerticalDatum::kEllipsoid ? "WGS84 ellipsoid" : "MSL"; }

std::optional<VerticalDatum> ParseVerticalDatum(const std::string& name) {
  for (const VerticalDatum d : {VerticalDatum::kEllipsoid, VerticalDatum::kMsl})
    if (name == VerticalDatumName(d)) return d;
  return std::nullopt;
}

std::optional<Eigen::Matrix3d> TelemetryAttitude(const telemetry::TelemetrySample& t) {
  if (!t.platform_heading || !t.platform_pitch || !t.platform_roll || !t.sensor_relative_azimuth ||
      !t.sensor_relative_elevation || !t.sensor_relative_roll)
    return std::nullopt;
  telemetry::St0601Attitude a;
  a.platform_heading = *t.platform_heading;
  a.platform_pitch = *t.platform_pitch;
  a.platform_roll = *t.platform_roll;
  a.sensor_relative_azimuth = *t.sensor_relative_azimuth;
  a.sensor_relative_elevation = *t.sensor_relative_elevation;
  a.sensor_relative_roll = *t.sensor_relative_roll;
  return telemetry::CameraToEnuFromSt0601(a);
}

PairedTelemetry PairTelemetry(const io::FramesIndex& index, const core::Reconstruction& rec,
                              const std::vector<telemetry::TelemetryTrack>* tracks, int min_cameras,
                              const std::string& where) {
  PairedTelemetry out;
  std::map<std::string, std::vector<TrajectoryKnot>> knots_by_source;
  for (const auto& f : index.frames) {
    const core::Image* img = rec.FindImageByName(f.name);
    if (img) knots_by_source[f.source].push_back({f.timestamp, img->pose.Centre(), img->pose.q});
    if (!f.telemetry) continue;
    const telemetry::TelemetrySample& s = *f.telemetry;
    if (!HasPosition(s)) continue;
    ++out.frames_with_position;
    if (img) out.keyframes.push_back(MakePair(f.name, img->pose.Centre(), img->pose.q, s));
  }
  if (out.frames_with_position == 0)
    throw Error(where + ": no frame carries a telemetry position (georef needs KLV, DJI SRT or GPS)");
  if (static_cast<int>(out.keyframes.size()) < min_cameras)
    throw Error(fmt::format("georef: only {} registered frames have telemetry positions ({} needed)",
                            out.keyframes.size(), min_cameras));
  if (tracks) {
    out.track_file = true;
    for (const auto& track : *tracks) {
      const auto it = knots_by_source.find(track.source);
      if (it == knots_by_source.end() || it->second.size() < 2) continue;
      const CameraTrajectory traj(it->second);
      for (const auto& s : track.samples) {
        if (!HasPosition(s)) continue;
        ++out.track_samples;
        const auto k = traj.At(s.time);
        if (!k) continue;
        ++out.track_spanned;
        out.track.push_back(MakePair("", k->centre, k->rotation, s));
        out.track.back().track = static_cast<int>(std::distance(knots_by_source.begin(), it));
      }
    }
    if (out.track.size() <= out.keyframes.size()) out.track.clear();  // nothing gained over the keyframes
  }
  const auto& fit = out.fit();
  const bool hae = std::all_of(fit.begin(), fit.end(), [](const GeorefPair& p) { return p.hae.has_value(); });
  out.datum = hae ? VerticalDatum::kEllipsoid : VerticalDatum::kMsl;
  for (auto* set : {&out.keyframes, &out.track})
    for (auto& p : *set) p.pos.alt = hae && p.hae ? *p.hae : (p.msl ? *p.msl : *p.hae);
  return out;
}

std::optional<double> FrameCentreHeightFromRange(const GeorefPair& p, const LocalFrame& frame) {
  if (!p.frame_centre || !p.slant_range || !(*p.slant_range > 0)) return std::nullopt;
  const Eigen::Vector3d s = frame.ToEnu(p.pos);
  const Eigen::Vector3d f = frame.ToEnu({p.frame_centre->lat, p.frame_centre->lon, p.pos.alt});
  const double horizontal = (f - s).head<2>().norm();
  if (!(horizontal < *p.slant_range)) return std::nullopt;
  // ENU z of the point at the slant range, back to a height in the pair's datum at the frame centre.
  const Eigen::Vector3d at_range(f.x(), f.y(),
                                 s.z() - std::sqrt(*p.slant_range * *p.slant_range - horizontal * horizontal));
  return frame.ToGeodetic(at_range).alt;
}

GeoPoint TelemetryCentroid(const std::vector<GeorefPair>& pairs) {
  const LocalFrame provisional(pairs.front().pos);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pairs) mean += provisional.ToEnu(p.pos);
  return provisional.ToGeodetic(mean / static_cast<double>(pairs.size()));
}

double ResidualAutocorrelation(const std::vector<GeorefPair>& pairs, const std::vector<Eigen::Vector3d>& residual,
                               const std::vector<char>& flagged) {
  double num = 0, den = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!flagged[i]) continue;
    den += residual[i].squaredNorm();
    if (i + 1 < pairs.size() && flagged[i + 1] && pairs[i + 1].track == pairs[i].track)
      num += residual[i].dot(residual[i + 1]);
  }
  return den > 0 ? std::clamp(num / den, 0.0, 0.999) : 0.0;
}

}  // namespace fmv3d::geo
