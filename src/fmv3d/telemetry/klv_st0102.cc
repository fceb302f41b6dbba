#include "fmv3d/telemetry/klv_st0102.h"

#include "fmv3d/telemetry/klv_decode_util.h"

namespace fmv3d::telemetry::klv {

const UlKey kSt0102Key = {0x06, 0x0E, 0x2B, 0x34, 0x02, 0x03, 0x01, 0x01,
                          0x0E, 0x01, 0x03, 0x03, 0x02, 0x00, 0x00, 0x00};

namespace {

enum class Kind { kEnum, kString, kUtf16, kUint, kBytes };

struct Spec {
  const char* name;
  Kind kind;
};

// ST 0102.12 Table 2; index = tag.
const Spec kSpecs[] = {
    {"Unknown Tag", Kind::kBytes},
    {"Security Classification", Kind::kEnum},
    {"Country Coding Method for 'Classifying Country' and 'Releasing Instructions'", Kind::kEnum},
    {"Classifying Country", Kind::kString},
    {"SCI/SHI Information", Kind::kString},
    {"Caveats", Kind::kString},
    {"Releasing Instructions", Kind::kString},
    {"Classified By", Kind::kString},
    {"Derived From", Kind::kString},
    {"Classification Reason", Kind::kString},
    {"Declassification Date", Kind::kString},
    {"Classification and Marking System", Kind::kString},
    {"Country Coding Method for 'Object Country Codes'", Kind::kEnum},
    {"Object Country Codes", Kind::kUtf16},
    {"Classification Comments", Kind::kString},
    {"UMID Video", Kind::kBytes},
    {"UMID Audio", Kind::kBytes},
    {"UMID Data", Kind::kBytes},
    {"UMID System", Kind::kBytes},
    {"Stream ID", Kind::kUint},
    {"Transport Stream ID", Kind::kUint},
    {"Item Designator ID", Kind::kBytes},
    {"Version", Kind::kUint},
    {"Country Coding Method Version Date for 'Classifying Country' and 'Releasing Instructions'", Kind::kString},
    {"Country Coding Method Version Date for 'Object Country Codes'", Kind::kString},
};
constexpr uint64_t kNumSpecs = sizeof(kSpecs) / sizeof(kSpecs[0]);

// UTF-16BE (ASCII range only is accepted, which is what country codes hold) to a string.
std::optional<std::string> Utf16Ascii(ByteSpan s) {
  if (s.size % 2) return std::nullopt;
  std::string out;
  for (size_t i = 0; i < s.size; i += 2) {
    if (s.data[i] != 0 || s.data[i + 1] >= 0x80) return std::nullopt;
    out += static_cast<char>(s.data[i + 1]);
  }
  return out;
}

}  // namespace

std::string St0102TagName(uint64_t tag) { return tag > 0 && tag < kNumSpecs ? kSpecs[tag].name : "Unknown Tag"; }

std::string St0102EnumName(uint64_t tag, uint64_t value) {
  static const std::vector<const char*> kClass = {"",       "Unclassified", "Restricted", "Confidential",
                                                  "Secret", "Top Secret"};
  static const std::vector<const char*> kMethod = {"",
                                                   "ISO-3166 Two Letter",
                                                   "ISO-3166 Three Letter",
                                                   "FIPS 10-4 Two Letter",
                                                   "FIPS 10-4 Four Letter",
                                                   "ISO-3166 Numeric",
                                                   "1059 Two Letter",
                                                   "1059 Three Letter",
                                                   "Omitted Value",
                                                   "Omitted Value",
                                                   "FIPS 10-4 Mixed",
                                                   "ISO 3166 Mixed",
                                                   "STANAG 1059 Mixed",
                                                   "GENC Two Letter",
                                                   "GENC Three Letter",
                                                   "GENC Numeric",
                                                   "GENC Mixed"};
  const std::vector<const char*>* names = tag == 1 ? &kClass : (tag == 2 || tag == 12) ? &kMethod : nullptr;
  if (!names || value >= names->size()) return "";
  return (*names)[value];
}

bool DecodeSt0102Items(ByteSpan set, std::vector<Item>* items, ParseStats* stats) {
  std::vector<RawLocalItem> raw;
  if (!SplitLocalSet(set, &raw)) return false;
  for (const auto& r : raw) {
    Item item;
    item.tag = r.tag;
    item.name = St0102TagName(r.tag);
    const Kind kind = r.tag > 0 && r.tag < kNumSpecs ? kSpecs[r.tag].kind : Kind::kBytes;
    bool ok = true;
    switch (kind) {
      case Kind::kEnum:
        ok = r.value.size == 1;
        if (ok) item.value = EnumJson(r.value.data[0], St0102EnumName(r.tag, r.value.data[0]));
        break;
      case Kind::kString: {
        const auto s = Utf8String(r.value);
        ok = s.has_value();
        if (ok) item.value = *s;
        break;
      }
      case Kind::kUtf16: {
        // ST 0102.12 mandates UTF-16; older files used ASCII, accept both.
        auto s = Utf16Ascii(r.value);
        if (!s) s = Utf8String(r.value);
        ok = s.has_value();
        if (ok) item.value = *s;
        break;
      }
      case Kind::kUint:
        ok = r.value.size >= 1 && r.value.size <= 8;
        if (ok) item.value = ReadUintBE(r.value);
        break;
      case Kind::kBytes:
        ok = false;
        break;
    }
    if (!ok) {
      if (kind != Kind::kBytes) ++stats->bad_items;
      item.parsed = false;
      item.value = nullptr;
      item.unparsed.assign(r.value.data, r.value.data + r.value.size);
    }
    items->push_back(std::move(item));
  }
  return true;
}

}  // namespace fmv3d::telemetry::klv
