#include "fmv3d/telemetry/klv_decode_util.h"

#include <cstring>

namespace fmv3d::telemetry::klv {

std::optional<std::string> Utf8String(ByteSpan s) {
  size_t i = 0;
  while (i < s.size) {
    const uint8_t c = s.data[i];
    size_t n = 0;
    uint32_t cp = 0;
    if (c < 0x80) {
      ++i;
      continue;
    } else if ((c & 0xE0) == 0xC0) {
      n = 1, cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      n = 2, cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      n = 3, cp = c & 0x07;
    } else {
      return std::nullopt;
    }
    if (i + n >= s.size) return std::nullopt;  // continuation bytes run past the end
    for (size_t k = 1; k <= n; ++k) {
      const uint8_t cc = s.data[i + k];
      if ((cc & 0xC0) != 0x80) return std::nullopt;
      cp = (cp << 6) | (cc & 0x3F);
    }
    // Reject overlong forms, surrogates and values beyond U+10FFFF.
    if ((n == 1 && cp < 0x80) || (n == 2 && cp < 0x800) || (n == 3 && cp < 0x10000) || cp > 0x10FFFF ||
        (cp >= 0xD800 && cp <= 0xDFFF))
      return std::nullopt;
    i += n + 1;
  }
  return std::string(reinterpret_cast<const char*>(s.data), s.size);
}

nlohmann::json EnumJson(uint64_t v, const std::string& name) {
  nlohmann::json j = {{"integer", v}};
  if (!name.empty()) j["string"] = name;
  return j;
}

nlohmann::json ItemsJson(const std::vector<Item>& items) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& it : items) j.push_back(ToJson(it));
  return j;
}

std::optional<double> ReadFloatBE(ByteSpan s) {
  if (s.size == 4) {
    const uint32_t u = static_cast<uint32_t>(ReadUintBE(s));
    float f;
    std::memcpy(&f, &u, 4);
    return static_cast<double>(f);
  }
  if (s.size == 8) {
    const uint64_t u = ReadUintBE(s);
    double d;
    std::memcpy(&d, &u, 8);
    return d;
  }
  return std::nullopt;
}

}  // namespace fmv3d::telemetry::klv
