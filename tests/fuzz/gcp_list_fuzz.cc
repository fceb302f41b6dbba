// libFuzzer target for OpenDroneMap's gcp_list.txt (geo/gcp_list.h): any text parses without a crash or an
// ASan/UBSan finding (the CRS line goes through GDAL/OGR), problems come out as messages, and a list that parses
// cleanly formats to text that parses to the same lines.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fmv3d/geo/gcp_list.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d;
  if (size > 4096) return 0;  // one GDAL CRS lookup per input; long inputs add nothing
  std::vector<std::string> errors;
  const geo::GcpList list = geo::ParseGcpList(std::string(reinterpret_cast<const char*>(data), size), &errors);
  io::FrameTable frames;
  frames["a.png"] = {64, 48, 10};
  geo::CheckGcpList(list, frames, &errors);
  (void)geo::GroupGcps(list);
  if (errors.empty()) {
    std::vector<std::string> again;
    const geo::GcpList b = geo::ParseGcpList(geo::FormatGcpList(list), &again);
    if (!again.empty() || b.lines.size() != list.lines.size()) __builtin_trap();
    for (size_t i = 0; i < b.lines.size(); ++i)
      if (b.lines[i].geo != list.lines[i].geo || b.lines[i].image != list.lines[i].image ||
          b.lines[i].IsCheck() != list.lines[i].IsCheck())
        __builtin_trap();
  }
  return 0;
}
