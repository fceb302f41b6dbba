// libFuzzer target for the GoPro GPMF parser (telemetry/gpmf.h) and the telemetry built from it
// (telemetry/gpmf_telemetry.h): no crash, no ASan/UBSan finding, every stream's values a whole number of
// samples, and every kept position screened (finite, on the globe).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "fmv3d/telemetry/gpmf.h"
#include "fmv3d/telemetry/gpmf_telemetry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d::telemetry;
  gpmf::ParseStats stats;
  for (const auto& s : gpmf::ParsePayload(data, size, &stats))
    if (s.elements == 0 || s.values.size() != s.samples() * s.elements) __builtin_trap();
  // Two payloads of the same bytes: timing across payloads and the CORI attachment run too.
  GpmfPayload p;
  p.bytes.assign(data, data + size);
  const GpmfTelemetry t = TelemetryFromGpmf({p, {1.0, 0.0, p.bytes}});
  for (const auto& s : t.samples) {
    if (!s.sensor_latitude) continue;
    if (!std::isfinite(*s.sensor_latitude) || std::abs(*s.sensor_latitude) > 90) __builtin_trap();
    (void)ToJson(s).dump();
  }
  return 0;
}
