#include "fmv3d/telemetry/gpmf_telemetry.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/avutil.h>
}

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/av_demux.h"

namespace fmv3d::telemetry {
namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Which position layout a stream has, if any.
enum class PositionKind { kNone, kGps5, kGps9, kOther };

PositionKind KindOf(const gpmf::Stream& s) {
  if (s.key == "GPS5" && s.elements >= 3) return PositionKind::kGps5;
  if (s.key == "GPS9" && s.elements >= 9) return PositionKind::kGps9;
  if (s.elements < 3 || s.key == "ACCL" || s.key == "GYRO" || s.key == "CORI" || s.key == "GRAV")
    return PositionKind::kNone;
  const bool units =
      s.units.size() >= 3 && Lower(s.units[0]) == "deg" && Lower(s.units[1]) == "deg" && Lower(s.units[2]) == "m";
  const std::string name = Lower(s.name);
  const bool named = name.find("lat") != std::string::npos && name.find("lon") != std::string::npos;
  return units || named ? PositionKind::kOther : PositionKind::kNone;
}

// GPSU "yymmddhhmmss.sss" (UTC, years from 2000) → seconds since 1970, nullopt when malformed.
std::optional<double> ParseGpsu(const std::string& s) {
  int yy, mo, dd, hh, mi;
  double ss;
  if (s.size() < 12 || std::sscanf(s.c_str(), "%2d%2d%2d%2d%2d%lf", &yy, &mo, &dd, &hh, &mi, &ss) != 6)
    return std::nullopt;
  if (mo < 1 || mo > 12 || dd < 1 || dd > 31 || hh > 23 || mi > 59 || !(ss >= 0 && ss < 61)) return std::nullopt;
  // Days from 1970 of 20yy-mo-dd (civil calendar).
  int64_t y = 2000 + yy - (mo <= 2);
  const int64_t era = y / 400;
  const int64_t yoe = y - era * 400;
  const int64_t doy = (153 * (mo > 2 ? mo - 3 : mo + 9) + 2) / 5 + dd - 1;
  const int64_t days = era * 146097 + yoe * 365 + yoe / 4 - yoe / 100 + doy - 719468;
  return static_cast<double>(days) * 86400.0 + hh * 3600.0 + mi * 60.0 + ss;
}

struct Orientation {
  double time;
  std::array<double, 4> q;  // w, x, y, z
};

void SetOrientation(const Orientation& o, TelemetrySample* s) {
  s->camera_orientation_w = o.q[0];
  s->camera_orientation_x = o.q[1];
  s->camera_orientation_y = o.q[2];
  s->camera_orientation_z = o.q[3];
}

}  // namespace

std::vector<GpmfPayload> ReadGpmfPayloads(const std::filesystem::path& path) {
  std::vector<GpmfPayload> out;
  const auto is_gpmd = [](const AVStream& s) {
    return s.codecpar->codec_type == AVMEDIA_TYPE_DATA && s.codecpar->codec_tag == MKTAG('g', 'p', 'm', 'd');
  };
  DemuxPackets(path, is_gpmd, [&](const DemuxedPacket& pkt) {
    if (pkt.size == 0) return;
    GpmfPayload p;
    p.time = pkt.time ? *pkt.time : (out.empty() ? 0.0 : out.back().time + 1.0);
    p.duration = pkt.duration;
    p.bytes.assign(pkt.data, pkt.data + pkt.size);
    out.push_back(std::move(p));
  });
  return out;
}

GpmfTelemetry TelemetryFromGpmf(const std::vector<GpmfPayload>& payloads, const FixQualityOptions& fix) {
  GpmfTelemetry out;
  std::vector<Orientation> orientations;
  for (size_t pi = 0; pi < payloads.size(); ++pi) {
    const GpmfPayload& p = payloads[pi];
    double duration = p.duration;
    if (!(duration > 0)) duration = pi + 1 < payloads.size() ? payloads[pi + 1].time - p.time : 1.0;
    if (!(duration > 0) || duration > 60) duration = 1.0;
    ++out.payloads;
    for (const gpmf::Stream& s : gpmf::ParsePayload(p.bytes.data(), p.bytes.size(), &out.parse)) {
      const size_t n = s.samples();
      out.stream_samples[s.key] += n;
      if (!s.name.empty()) out.stream_names[s.key] = s.name;
      if (!s.device.empty() && std::find(out.devices.begin(), out.devices.end(), s.device) == out.devices.end())
        out.devices.push_back(s.device);
      if (s.key == "CORI" && s.elements == 4) {
        for (size_t k = 0; k < n; ++k) {
          const std::array<double, 4> q{s.at(k, 0), s.at(k, 1), s.at(k, 2), s.at(k, 3)};
          const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
          if (!(norm > 0.5 && norm < 1.5)) continue;  // not a rotation: garbage
          orientations.push_back({p.time + duration * k / n, {q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm}});
        }
        continue;
      }
      const PositionKind kind = KindOf(s);
      if (kind == PositionKind::kNone) continue;
      const bool msl = s.altitude_system.rfind("MSL", 0) == 0;
      const std::optional<double> utc = ParseGpsu(s.gps_utc);
      for (size_t k = 0; k < n; ++k) {
        TelemetrySample t;
        t.time = p.time + duration * k / n;
        t.source = kind == PositionKind::kOther ? "GPMF-" + s.key : "GPMF";
        t.sensor_latitude = s.at(k, 0);
        t.sensor_longitude = s.at(k, 1);
        (msl ? t.sensor_altitude_msl : t.sensor_altitude_hae) = s.at(k, 2);
        if (kind == PositionKind::kGps9) {
          t.gps_dop = s.at(k, 7);
          t.gps_fix = s.at(k, 8);
          const double days = s.at(k, 5), secs = s.at(k, 6);
          if (std::isfinite(days) && std::isfinite(secs) && days >= 0 && days < 1e5 && secs >= 0 && secs < 86401)
            t.unix_time_us = static_cast<uint64_t>(std::llround(((days + 10957) * 86400 + secs) * 1e6));
        } else {
          t.gps_dop = s.gps_dop;
          t.gps_fix = s.gps_fix;
          if (utc) t.unix_time_us = static_cast<uint64_t>(std::llround((*utc + duration * k / n) * 1e6));
        }
        for (auto* v : {&t.sensor_latitude, &t.sensor_longitude, &t.sensor_altitude_hae, &t.sensor_altitude_msl,
                        &t.gps_dop, &t.gps_fix})
          if (*v && !std::isfinite(**v)) v->reset();
        const FixRejection r = ScreenFix(t, fix);
        out.fixes.Add(r);
        if (r == FixRejection::kNone) out.samples.push_back(std::move(t));
      }
    }
  }
  const auto by_time = [](const auto& a, const auto& b) { return a.time < b.time; };
  std::stable_sort(out.samples.begin(), out.samples.end(), by_time);
  std::stable_sort(orientations.begin(), orientations.end(), by_time);
  if (out.samples.empty()) {
    for (const Orientation& o : orientations) {
      TelemetrySample t;
      t.time = o.time;
      t.source = "GPMF";
      SetOrientation(o, &t);
      out.samples.push_back(std::move(t));
    }
  } else if (!orientations.empty()) {
    for (TelemetrySample& t : out.samples) {
      auto hi = std::lower_bound(orientations.begin(), orientations.end(), t.time,
                                 [](const Orientation& o, double v) { return o.time < v; });
      if (hi == orientations.end() || (hi != orientations.begin() && t.time - (hi - 1)->time < hi->time - t.time)) --hi;
      SetOrientation(*hi, &t);
    }
  }
  return out;
}

GpmfTelemetry ReadGpmfTelemetry(const std::filesystem::path& video, const FixQualityOptions& fix) {
  return TelemetryFromGpmf(ReadGpmfPayloads(video), fix);
}

}  // namespace fmv3d::telemetry
