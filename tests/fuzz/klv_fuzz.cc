// libFuzzer target for the KLV parsers (and the DJI SRT reader, fed the same bytes as text): whatever the
// bytes, parsing, JSON conversion and telemetry extraction must neither crash nor trip ASan/UBSan.
// Build and run: `make fuzz` (FUZZ_TARGETS=klv_fuzz to run only this one).
// fuzz-sources: io/klv*.cc io/telemetry.cc io/dji_srt.cc
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fmv3d/telemetry/dji_srt.h"
#include "fmv3d/telemetry/klv.h"
#include "fmv3d/telemetry/telemetry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d::telemetry;
  std::vector<klv::Packet> packets;
  klv::ParseStats stats;
  klv::ParseBuffer(klv::ByteSpan(data, size), &packets, &stats);
  if (packets.size() != stats.packets) __builtin_trap();  // the count must match what was kept
  std::vector<TelemetrySample> samples;
  for (const auto& p : packets) {
    // dump() throws on invalid UTF-8; the decoders must never let such a string through.
    const std::string text = klv::ToJson(p).dump();
    (void)text;
    if (auto s = SampleFromPacket(p)) samples.push_back(*s);
  }
  for (const auto& s : samples) (void)ToJson(s).dump();
  if (!samples.empty()) (void)InterpolateTelemetry(samples, samples.front().time + 0.01);
  if (size < 4096) {
    const auto srt = ParseDjiSrt(std::string(reinterpret_cast<const char*>(data), size));
    for (const auto& s : srt) (void)ToJson(s).dump();
  }
  return 0;
}
