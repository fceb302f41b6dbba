// MISB ST 0102 (Security Metadata Local Set): decoded standalone (its own top-level key) or nested in
// ST 0601 tag 48. Enumerations (classification, country coding methods) come out as {"integer","string"};
// tag 13 (object country codes, UTF-16BE in ST 0102.12) as a string.
#pragma once

#include <string>
#include <vector>

#include "fmv3d/telemetry/klv.h"

namespace fmv3d::telemetry::klv {

extern const UlKey kSt0102Key;  // 06 0E 2B 34 02 03 01 01 0E 01 03 03 02 00 00 00

bool DecodeSt0102Items(ByteSpan set, std::vector<Item>* items, ParseStats* stats);
std::string St0102TagName(uint64_t tag);
std::string St0102EnumName(uint64_t tag, uint64_t value);

}  // namespace fmv3d::telemetry::klv
