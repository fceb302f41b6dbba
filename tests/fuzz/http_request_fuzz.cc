// libFuzzer target for the console server's request validation (src/fmv3d/server/validation.cc, which needs only
// nlohmann_json and the standard library): JSON bodies, query values, upload names and paths. Whatever the
// bytes, nothing may crash, and what is accepted must keep the rules: a resolved path stays inside its root, an
// upload name is one harmless component, job stages are stage names.
// Run: build-fuzz/tests/fuzz/http_request_fuzz -max_total_time=300 CORPUS_DIR
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "fmv3d/server/validation.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace fmv3d::server;
  if (size == 0) return 0;
  const uint8_t selector = data[0];
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    switch (selector % 7) {
      case 0: {
        const JobRequest r = ParseJobRequest(text);
        if ((!r.from.empty() && !IsStageName(r.from)) || (!r.until.empty() && !IsStageName(r.until))) __builtin_trap();
        for (const auto& in : r.inputs)
          if (in.empty() || in.find('\0') != std::string::npos) __builtin_trap();
        break;
      }
      case 1:
        if (!IsValidWorkspaceName(ParseCreateWorkspace(text))) __builtin_trap();
        break;
      case 2: {
        const LatLon p = ParseLatLon(text, "from");
        if (!(p.lat >= -90 && p.lat <= 90 && p.lon >= -180 && p.lon <= 180)) __builtin_trap();
        break;
      }
      case 3: {
        const int n = ParseBoundedInt(text, 2, 5000, "n");
        if (n < 2 || n > 5000) __builtin_trap();
        break;
      }
      case 4: {
        const std::string name = SanitiseUploadName(text);
        if (name.empty() || name.find('/') != std::string::npos || name.front() == '.' || name.size() > 128)
          __builtin_trap();
        break;
      }
      case 5: {
        // A root that does not exist: resolution stays lexical, and must never leave it.
        static const std::filesystem::path root = "/nonexistent-fmv3d-fuzz-root/ws";
        if (const auto p = ResolveInside(root, text)) {
          if (!IsWithin(root, *p)) __builtin_trap();
        }
        break;
      }
      case 6: {
        const size_t half = text.size() / 2;
        const bool eq = ConstantTimeEquals(text.substr(0, half), text.substr(half));
        if (eq != (text.substr(0, half) == text.substr(half))) __builtin_trap();
        break;
      }
    }
  } catch (const RequestError&) {
  }
  return 0;
}
