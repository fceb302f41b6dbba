// libFuzzer target for the DJI .SRT subtitle reader (telemetry/dji_srt.h): any text parses without a crash or
// an ASan/UBSan finding, samples come out with finite times, and interpolation over them is safe.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fmv3d/telemetry/dji_srt.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d::telemetry;
  const auto samples = ParseDjiSrt(std::string(reinterpret_cast<const char*>(data), size));
  for (const auto& s : samples) {
    if (!std::isfinite(s.time)) __builtin_trap();
    (void)ToJson(s).dump();
  }
  if (!samples.empty()) (void)InterpolateTelemetry(samples, samples.front().time + 0.01);
  return 0;
}
