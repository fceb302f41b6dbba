// libFuzzer target for WS/manual/tiepoints.json (io/tiepoints.h): any bytes parse without a crash or an ASan/UBSan
// finding and only report problems as messages; whatever parses cleanly is written back identically, and checked
// against a small frame table without a throw.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fmv3d/io/tiepoints.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d::io;
  std::vector<std::string> errors;
  const TiePoints t = ParseTiePoints(std::string(reinterpret_cast<const char*>(data), size), &errors);
  FrameTable frames;
  frames["a.png"] = {64, 48, 10};
  frames["b.png"] = {64, 48, 10};
  CheckTiePoints(t, frames, &errors);
  if (errors.empty()) {
    std::vector<std::string> again;
    const TiePoints u = TiePointsFromJson(TiePointsToJson(t), &again);
    if (!again.empty() || TiePointsToJson(u) != TiePointsToJson(t)) __builtin_trap();
  }
  (void)JoinErrors(errors);
  return 0;
}
