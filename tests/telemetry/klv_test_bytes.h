// Builders of KLV byte arrays for the KLV tests (hand-made packets, encoded by the standards' rules).
#pragma once

#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "fmv3d/telemetry/klv.h"
#include "fmv3d/telemetry/klv_st0601.h"

namespace fmv3d::telemetry::klv::test {

using Bytes = std::vector<uint8_t>;

inline Bytes Ber(size_t n) {
  if (n < 128) return {static_cast<uint8_t>(n)};
  Bytes be;
  for (size_t v = n; v; v >>= 8) be.insert(be.begin(), static_cast<uint8_t>(v & 0xff));
  be.insert(be.begin(), static_cast<uint8_t>(0x80 | be.size()));
  return be;
}

inline void Append(Bytes* out, const Bytes& b) { out->insert(out->end(), b.begin(), b.end()); }

// One local-set item: tag (< 128), BER length, value.
inline Bytes Tlv(uint8_t tag, const Bytes& value) {
  Bytes out{tag};
  Append(&out, Ber(value.size()));
  Append(&out, value);
  return out;
}

inline Bytes Str(const std::string& s) { return Bytes(s.begin(), s.end()); }

inline Bytes BigEndian(uint64_t v, size_t n) {
  Bytes out(n);
  for (size_t i = 0; i < n; ++i) out[n - 1 - i] = static_cast<uint8_t>(v >> (8 * i));
  return out;
}

inline Bytes KeyBytes(const UlKey& k) { return Bytes(k.begin(), k.end()); }

// A complete ST 0601 packet: key, BER length, the items, and a correct checksum (unless `corrupt`).
inline Bytes St0601Packet(std::initializer_list<Bytes> items, bool corrupt = false) {
  Bytes set;
  for (const auto& it : items) Append(&set, it);
  set.push_back(0x01);
  set.push_back(0x02);
  Bytes out = KeyBytes(kSt0601Key);
  Append(&out, Ber(set.size() + 2));
  Append(&out, set);
  const uint16_t sum = St0601Checksum(ByteSpan(out.data(), out.size())) ^ (corrupt ? 0x0100 : 0);
  out.push_back(static_cast<uint8_t>(sum >> 8));
  out.push_back(static_cast<uint8_t>(sum & 0xff));
  return out;
}

}  // namespace fmv3d::telemetry::klv::test
