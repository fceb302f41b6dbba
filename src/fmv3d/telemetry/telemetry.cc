#include "fmv3d/telemetry/telemetry.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/avutil.h>
}

#include <algorithm>
#include <cmath>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/telemetry/attitude.h"
#include "fmv3d/telemetry/av_demux.h"
#include "fmv3d/telemetry/klv_eg0104.h"
#include "fmv3d/telemetry/klv_st0601.h"

namespace fmv3d::telemetry {

namespace {

bool IsKlvStream(const AVStream* st) {
  const AVCodecParameters* par = st->codecpar;
  if (par->codec_type != AVMEDIA_TYPE_DATA) return false;
  if (par->codec_id == AV_CODEC_ID_SMPTE_KLV) return true;
  // Some muxers tag KLV only by its registration descriptor ("KLVA").
  return par->codec_tag == MKTAG('K', 'L', 'V', 'A');
}

std::optional<double> Number(const klv::Item* it) {
  if (!it || !it->parsed || !it->value.is_number()) return std::nullopt;
  const double v = it->value.get<double>();
  if (!std::isfinite(v)) return std::nullopt;
  return v;
}

}  // namespace

std::vector<klv::Packet> ReadVideoKlv(const std::filesystem::path& path, TelemetryStats* stats) {
  TelemetryStats local;
  TelemetryStats& st = stats ? *stats : local;
  std::vector<klv::Packet> out;
  double last_time = 0.0;
  std::map<int, size_t> per_stream;
  DemuxOptions o;
  o.with_video_timing = true;  // asynchronous KLV without a PTS borrows the last video packet's time
  DemuxPackets(
      path, [](const AVStream& s) { return IsKlvStream(&s); },
      [&](const DemuxedPacket& pkt) {
        if (pkt.wanted) {
          const size_t before = out.size();
          klv::ParseBuffer(klv::ByteSpan(pkt.data, pkt.size), &out, &st.klv);
          for (size_t i = before; i < out.size(); ++i) {
            out[i].stream_index = pkt.stream_index;
            out[i].time_seconds = pkt.time ? *pkt.time : last_time;
          }
          per_stream[pkt.stream_index] += out.size() - before;
        }
        if (pkt.time) last_time = *pkt.time;
      },
      o);
  for (const auto& [idx, n] : per_stream) st.packets_per_stream.emplace_back(idx, n);
  return out;
}

std::optional<TelemetrySample> SampleFromPacket(const klv::Packet& p) {
  using namespace klv;
  TelemetrySample s;
  s.time = p.time_seconds.value_or(0.0);
  if (p.standard == Standard::kSt0601) {
    s.source = "ST0601";
    auto num = [&](uint64_t tag) { return Number(p.Find(tag)); };
    s.sensor_latitude = num(kTagSensorLatitude);
    s.sensor_longitude = num(kTagSensorLongitude);
    s.sensor_altitude_msl = num(kTagSensorTrueAltitude);
    s.sensor_altitude_hae = num(kTagSensorEllipsoidHeightExtended);
    if (!s.sensor_altitude_hae) s.sensor_altitude_hae = num(kTagSensorEllipsoidHeight);
    s.platform_heading = num(kTagPlatformHeading);
    // The "full" angles (tags 90/91) have the wider range and finer resolution: prefer them.
    s.platform_pitch = num(kTagPlatformPitchFull);
    if (!s.platform_pitch) s.platform_pitch = num(kTagPlatformPitch);
    s.platform_roll = num(kTagPlatformRollFull);
    if (!s.platform_roll) s.platform_roll = num(kTagPlatformRoll);
    s.sensor_relative_azimuth = num(kTagSensorRelAzimuth);
    s.sensor_relative_elevation = num(kTagSensorRelElevation);
    s.sensor_relative_roll = num(kTagSensorRelRoll);
    s.horizontal_fov = num(kTagSensorHfov);
    s.vertical_fov = num(kTagSensorVfov);
    s.slant_range = num(kTagSlantRange);
    s.frame_center_latitude = num(kTagFrameCenterLatitude);
    s.frame_center_longitude = num(kTagFrameCenterLongitude);
    s.frame_center_elevation = num(kTagFrameCenterElevation);
    s.frame_center_hae = num(kTagFrameCenterHae);
    const Item* ts = p.Find(kTagPrecisionTimestamp);
    if (ts && ts->parsed && ts->value.is_number_unsigned()) s.unix_time_us = ts->value.get<uint64_t>();
    return s;
  }
  if (p.standard == Standard::kEg0104) {
    s.source = "EG0104";
    auto num = [&](Eg0104Field f) { return Number(p.Find(Eg0104KeyOf(f))); };
    s.sensor_latitude = num(Eg0104Field::kDeviceLatitude);
    s.sensor_longitude = num(Eg0104Field::kDeviceLongitude);
    s.sensor_altitude_msl = num(Eg0104Field::kDeviceAltitude);
    // EG0104 floats may carry headings in (-180, 180]; ST 0601's convention is [0, 360).
    s.platform_heading = num(Eg0104Field::kPlatformHeading);
    if (s.platform_heading) s.platform_heading = Wrap360(*s.platform_heading);
    s.platform_pitch = num(Eg0104Field::kPlatformPitch);
    s.platform_roll = num(Eg0104Field::kPlatformRoll);
    s.sensor_angle_to_north = num(Eg0104Field::kAngleToNorth);
    s.sensor_obliquity = num(Eg0104Field::kObliquityAngle);
    s.sensor_relative_roll = num(Eg0104Field::kSensorRollAngle);
    if (s.sensor_angle_to_north && s.platform_heading)
      s.sensor_relative_azimuth = Wrap360(*s.sensor_angle_to_north - *s.platform_heading);
    s.horizontal_fov = num(Eg0104Field::kHorizontalFov);
    s.vertical_fov = num(Eg0104Field::kVerticalFov);
    s.slant_range = num(Eg0104Field::kSlantRange);
    s.frame_center_latitude = num(Eg0104Field::kFrameCenterLatitude);
    s.frame_center_longitude = num(Eg0104Field::kFrameCenterLongitude);
    s.frame_center_elevation = num(Eg0104Field::kFrameCenterElevation);
    const Item* ts = p.Find(Eg0104KeyOf(Eg0104Field::kUserDefinedTimestamp));
    if (ts && ts->parsed && ts->value.is_number_unsigned()) s.unix_time_us = ts->value.get<uint64_t>();
    return s;
  }
  return std::nullopt;
}

std::vector<TelemetrySample> ReadVideoTelemetry(const std::filesystem::path& path, TelemetryStats* stats) {
  std::vector<TelemetrySample> out;
  for (const auto& p : ReadVideoKlv(path, stats))
    if (auto s = SampleFromPacket(p)) out.push_back(std::move(*s));
  std::stable_sort(out.begin(), out.end(),
                   [](const TelemetrySample& a, const TelemetrySample& b) { return a.time < b.time; });
  return out;
}

namespace {

using Interp = core::TelemetryInterp;

// Interpolates along the shorter arc; the result keeps the convention of the inputs' range.
double Lerp(double a, double b, double w, Interp mode) {
  if (mode == Interp::kLinear) return a + w * (b - a);
  double d = std::fmod(b - a, 360.0);
  if (d > 180) d -= 360;
  if (d < -180) d += 360;
  double v = a + w * d;
  if (mode == Interp::kAngle360) return Wrap360(v);
  v = std::fmod(v + 180.0, 360.0);  // longitude-like: [-180, 180)
  return (v < 0 ? v + 360.0 : v) - 180.0;
}

}  // namespace

std::optional<TelemetrySample> InterpolateTelemetry(const std::vector<TelemetrySample>& samples, double t,
                                                    double max_extrapolation) {
  if (samples.empty() || !std::isfinite(t)) return std::nullopt;
  if (t <= samples.front().time) {
    if (samples.front().time - t > max_extrapolation) return std::nullopt;
    TelemetrySample s = samples.front();
    s.time = t;
    return s;
  }
  if (t >= samples.back().time) {
    if (t - samples.back().time > max_extrapolation) return std::nullopt;
    TelemetrySample s = samples.back();
    s.time = t;
    return s;
  }
  const auto hi = std::upper_bound(samples.begin(), samples.end(), t,
                                   [](double v, const TelemetrySample& s) { return v < s.time; });
  const TelemetrySample& b = *hi;
  const TelemetrySample& a = *(hi - 1);
  const double span = b.time - a.time;
  const double w = span > 0 ? (t - a.time) / span : 0.0;
  TelemetrySample s = w < 0.5 ? a : b;  // nearest, for discrete fields
  s.time = t;
  for (const auto& f : core::TelemetryFields()) {
    const auto& va = a.*(f.field);
    const auto& vb = b.*(f.field);
    if (va && vb && f.interp != Interp::kNearest) s.*(f.field) = Lerp(*va, *vb, w, f.interp);
    // else: the nearest sample's value (possibly empty) stays; a field only one side has is not invented.
  }
  if (a.unix_time_us && b.unix_time_us) {
    const double ua = static_cast<double>(*a.unix_time_us), ub = static_cast<double>(*b.unix_time_us);
    s.unix_time_us = static_cast<uint64_t>(std::llround(ua + w * (ub - ua)));
  }
  return s;
}

void WriteTelemetryTracks(const std::vector<TelemetryTrack>& tracks, const std::filesystem::path& path) {
  nlohmann::json j = {{"version", 1}, {"tracks", nlohmann::json::array()}};
  for (const auto& t : tracks) {
    nlohmann::json samples = nlohmann::json::array();
    for (const auto& s : t.samples) samples.push_back(ToJson(s));
    j["tracks"].push_back({{"source", t.source}, {"samples", std::move(samples)}});
  }
  core::WriteJson(path, j);
}

std::vector<TelemetryTrack> ReadTelemetryTracks(const std::filesystem::path& path) {
  const nlohmann::json j = core::ReadJson(path);
  std::vector<TelemetryTrack> out;
  try {
    if (!j.contains("tracks") || !j["tracks"].is_array()) throw Error("no \"tracks\" list");
    for (const auto& t : j["tracks"]) {
      TelemetryTrack track;
      track.source = t.at("source").get<std::string>();
      for (const auto& s : t.at("samples")) track.samples.push_back(TelemetryFromJson(s));
      std::stable_sort(track.samples.begin(), track.samples.end(),
                       [](const TelemetrySample& a, const TelemetrySample& b) { return a.time < b.time; });
      out.push_back(std::move(track));
    }
  } catch (const std::exception& e) {
    throw Error(path.string() + ": malformed telemetry track file (" + e.what() + ") — run `fmv3d frames` again");
  }
  return out;
}

}  // namespace fmv3d::telemetry
