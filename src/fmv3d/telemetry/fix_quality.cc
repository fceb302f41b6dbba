#include "fmv3d/telemetry/fix_quality.h"

#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::telemetry {

const char* FixRejectionText(FixRejection r) {
  switch (r) {
    case FixRejection::kNone:
      return "kept";
    case FixRejection::kNoPosition:
      return "no position";
    case FixRejection::kZeroFix:
      return "(0, 0) fix";
    case FixRejection::kOutOfRange:
      return "out of range";
    case FixRejection::kNoLock:
      return "no lock";
    case FixRejection::kPoorDop:
      return "DOP too large";
    case FixRejection::kPoorAccuracy:
      return "accuracy too poor";
  }
  return "?";
}

void FixQualityOptions::Check() const {
  if (!(max_dop > 0) || !(max_horizontal_accuracy > 0))
    throw Error("fix quality: the DOP and accuracy bounds must be positive");
}

FixRejection ScreenFix(const TelemetrySample& s, const FixQualityOptions& o) {
  if (!s.sensor_latitude || !s.sensor_longitude) return FixRejection::kNoPosition;
  const double lat = *s.sensor_latitude, lon = *s.sensor_longitude;
  if (!std::isfinite(lat) || !std::isfinite(lon) || std::abs(lat) > 90 || std::abs(lon) > 180)
    return FixRejection::kOutOfRange;
  if (std::abs(lat) < 1e-7 && std::abs(lon) < 1e-7) return FixRejection::kZeroFix;
  for (const auto& alt : {s.sensor_altitude_msl, s.sensor_altitude_hae})
    if (alt && !(*alt >= -1000 && *alt <= 20000)) return FixRejection::kOutOfRange;
  if (s.gps_fix && !(*s.gps_fix >= 2)) return FixRejection::kNoLock;
  if (s.gps_dop && !(*s.gps_dop <= o.max_dop)) return FixRejection::kPoorDop;
  if (s.horizontal_accuracy && !(*s.horizontal_accuracy <= o.max_horizontal_accuracy))
    return FixRejection::kPoorAccuracy;
  return FixRejection::kNone;
}

void FixCounts::Add(FixRejection r) {
  if (r == FixRejection::kNone)
    ++kept;
  else
    ++rejected[static_cast<size_t>(r)];
}

size_t FixCounts::Rejected() const {
  size_t n = 0;
  for (size_t i = 0; i < kFixRejectionCount; ++i)
    if (i != static_cast<size_t>(FixRejection::kNoPosition)) n += rejected[i];
  return n;
}

std::string FixCounts::Summary(const std::string& what) const {
  const size_t bad = Rejected();
  if (bad == 0) return "";
  std::string s = std::to_string(bad) + " of " + std::to_string(bad + kept) + " " + what + " dropped:";
  bool first = true;
  for (size_t i = 0; i < kFixRejectionCount; ++i) {
    if (i == static_cast<size_t>(FixRejection::kNoPosition) || rejected[i] == 0) continue;
    s += (first ? " " : ", ") + std::to_string(rejected[i]) + " " + FixRejectionText(static_cast<FixRejection>(i));
    first = false;
  }
  return s;
}

}  // namespace fmv3d::telemetry
