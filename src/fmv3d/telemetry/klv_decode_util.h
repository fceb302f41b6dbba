// Small helpers shared by the KLV set decoders (internal to io/klv*.cc).
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry::klv {

// The bytes as a string if they are valid UTF-8 (NUL allowed, as KWIVER keeps it), else nullopt: a JSON
// writer must never see invalid UTF-8.
std::optional<std::string> Utf8String(ByteSpan s);
// {"integer": v, "string": name} (name omitted when empty, i.e. not in the standard's list).
nlohmann::json EnumJson(uint64_t v, const std::string& name);
nlohmann::json ItemsJson(const std::vector<Item>& items);
// IEEE-754 big-endian float (4 bytes) or double (8 bytes); nullopt for other lengths.
std::optional<double> ReadFloatBE(ByteSpan s);

}  // namespace fmv3d::telemetry::klv
