#include "fmv3d/telemetry/klv.h"

#include <cmath>
#include <cstdio>
#include <cstring>

#include "fmv3d/telemetry/klv_eg0104.h"
#include "fmv3d/telemetry/klv_st0102.h"
#include "fmv3d/telemetry/klv_st0601.h"

namespace fmv3d::telemetry::klv {

bool Reader::ReadByte(uint8_t* b) {
  if (pos_ >= s_.size) return false;
  *b = s_.data[pos_++];
  return true;
}

bool Reader::ReadSpan(size_t n, ByteSpan* out) {
  if (n > remaining()) return false;
  *out = s_.Sub(pos_, n);
  pos_ += n;
  return true;
}

bool Reader::ReadBerLength(uint64_t* len) {
  const size_t start = pos_;
  uint8_t b = 0;
  if (!ReadByte(&b)) return false;
  if (b < 0x80) {
    *len = b;
    return true;
  }
  const size_t n = b & 0x7f;
  if (n == 0 || n > 8 || n > remaining()) {
    pos_ = start;
    return false;
  }
  uint64_t v = 0;
  for (size_t i = 0; i < n; ++i) v = (v << 8) | s_.data[pos_++];
  *len = v;
  return true;
}

bool Reader::ReadBerOid(uint64_t* value) {
  const size_t start = pos_;
  uint64_t v = 0;
  for (int i = 0; i < 9; ++i) {
    uint8_t b = 0;
    if (!ReadByte(&b)) break;
    v = (v << 7) | (b & 0x7f);
    if (!(b & 0x80)) {
      *value = v;
      return true;
    }
  }
  pos_ = start;
  return false;
}

uint64_t ReadUintBE(ByteSpan s) {
  uint64_t v = 0;
  for (size_t i = 0; i < s.size && i < 8; ++i) v = (v << 8) | s.data[i];
  return v;
}

int64_t ReadIntBE(ByteSpan s) {
  if (s.size == 0) return 0;
  const size_t n = s.size < 8 ? s.size : 8;
  uint64_t v = ReadUintBE(ByteSpan(s.data, n));
  if (n < 8 && (s.data[0] & 0x80)) v |= ~uint64_t{0} << (8 * n);  // sign-extend
  int64_t out;
  std::memcpy(&out, &v, sizeof out);  // two's complement reinterpretation without UB
  return out;
}

uint16_t St0601Checksum(ByteSpan s) {
  uint16_t sum = 0;
  for (size_t i = 0; i < s.size; ++i)
    sum = static_cast<uint16_t>(sum + (static_cast<uint16_t>(s.data[i]) << (8 * ((i + 1) % 2))));
  return sum;
}

uint16_t Crc16Ccitt(ByteSpan s) {
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < s.size; ++i) {
    crc ^= static_cast<uint16_t>(s.data[i]) << 8;
    for (int b = 0; b < 8; ++b)
      crc = (crc & 0x8000) ? static_cast<uint16_t>((crc << 1) ^ 0x1021) : static_cast<uint16_t>(crc << 1);
  }
  return crc;
}

double MapUnsigned(uint64_t v, size_t n, double lo, double hi) {
  const double max = std::ldexp(1.0, static_cast<int>(8 * n)) - 1.0;
  return lo + static_cast<double>(v) * (hi - lo) / max;
}

std::optional<double> MapSigned(int64_t v, size_t n, double range) {
  const double max = std::ldexp(1.0, static_cast<int>(8 * n - 1)) - 1.0;
  if (static_cast<double>(v) < -max) return std::nullopt;  // 0x80.. is the reserved error value
  return static_cast<double>(v) * range / max;
}

std::optional<double> DecodeImapb(ByteSpan s, double a, double b) {
  if (s.size == 0 || s.size > 8 || !(b > a)) return std::nullopt;
  const int b_pow = static_cast<int>(std::ceil(std::log2(b - a)));
  const int d_pow = static_cast<int>(8 * s.size) - 1;
  const double sf = std::ldexp(1.0, d_pow - b_pow);
  const double sr = std::ldexp(1.0, b_pow - d_pow);
  const double z_offset = (a < 0 && b > 0) ? sf * a - std::floor(sf * a) : 0.0;
  const uint64_t y = ReadUintBE(s);
  // The special values (ST 1201 Table: infinities, NaNs, user-defined) all have the two top bits set or
  // decode outside [a, b]; a valid encoding never reaches them.
  if ((s.data[0] & 0xC0) == 0xC0) return std::nullopt;
  const double x = sr * (static_cast<double>(y) - z_offset) + a;
  if (x < a - sr || x > b + sr) return std::nullopt;
  return x;
}

std::string UlHex(const UlKey& k) {
  std::string out;
  char buf[3];
  for (size_t i = 0; i < k.size(); ++i) {
    if (i && i % 4 == 0) out += ' ';
    std::snprintf(buf, sizeof buf, "%02x", k[i]);
    out += buf;
  }
  return out;
}

bool UlEqualIgnoringVersion(const UlKey& a, const UlKey& b) {
  for (size_t i = 0; i < a.size(); ++i)
    if (i != 7 && a[i] != b[i]) return false;
  return true;
}

std::string Base64(ByteSpan s) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((s.size + 2) / 3 * 4);
  for (size_t i = 0; i < s.size; i += 3) {
    const uint32_t b0 = s.data[i];
    const uint32_t b1 = i + 1 < s.size ? s.data[i + 1] : 0;
    const uint32_t b2 = i + 2 < s.size ? s.data[i + 2] : 0;
    const uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < s.size ? kAlphabet[(v >> 6) & 63] : '=';
    out += i + 2 < s.size ? kAlphabet[v & 63] : '=';
  }
  return out;
}

std::string KnownKeyName(const UlKey& k) {
  struct Known {
    UlKey key;
    const char* name;
  };
  static const Known kKnown[] = {
      {kSt0601Key, "MISB ST0601 Local Set"},
      {kEg0104Key, "MISB ST0104 Universal Set"},
      {kSt0102Key, "MISB ST0102 Local Set"},
      {{0x06, 0x0E, 0x2B, 0x34, 0x02, 0x0B, 0x01, 0x01, 0x0E, 0x01, 0x03, 0x03, 0x22, 0x00, 0x00, 0x00},
       "MISB ST1107 Local Set"},
      {{0x06, 0x0E, 0x2B, 0x34, 0x02, 0x03, 0x01, 0x01, 0x0E, 0x01, 0x03, 0x03, 0x1C, 0x00, 0x00, 0x00},
       "MISB ST1108 Local Set"},
      {{0x06, 0x0E, 0x2B, 0x34, 0x02, 0x0B, 0x01, 0x01, 0x0E, 0x01, 0x03, 0x03, 0x06, 0x00, 0x00, 0x00},
       "MISB ST0903 Local Set"},
  };
  for (const auto& kk : kKnown)
    if (UlEqualIgnoringVersion(k, kk.key)) return kk.name;
  return "Unknown";
}

const Item* Packet::Find(uint64_t tag) const {
  for (const auto& it : items)
    if (!it.key && it.tag == tag) return &it;
  return nullptr;
}

const Item* Packet::Find(const UlKey& key) const {
  for (const auto& it : items)
    if (it.key && UlEqualIgnoringVersion(*it.key, key)) return &it;
  return nullptr;
}

void ParseStats::Add(const ParseStats& o) {
  packets += o.packets;
  bad_checksum += o.bad_checksum;
  malformed += o.malformed;
  unknown_keys += o.unknown_keys;
  bad_items += o.bad_items;
  skipped_bytes += o.skipped_bytes;
}

bool SplitLocalSet(ByteSpan set, std::vector<RawLocalItem>* items) {
  Reader r(set);
  while (!r.empty()) {
    RawLocalItem it;
    it.offset = r.pos();
    uint64_t len = 0;
    if (!r.ReadBerOid(&it.tag) || !r.ReadBerLength(&len) || len > r.remaining() ||
        !r.ReadSpan(static_cast<size_t>(len), &it.value))
      return false;
    items->push_back(it);
  }
  return true;
}

namespace {

constexpr uint8_t kUlPrefix[4] = {0x06, 0x0E, 0x2B, 0x34};

bool StartsWithPrefix(const uint8_t* p, size_t n) { return n >= 4 && std::memcmp(p, kUlPrefix, 4) == 0; }

// Finds the next occurrence of the SMPTE label prefix at or after `from`; size if none.
size_t NextPrefix(ByteSpan s, size_t from) {
  for (size_t i = from; i + 4 <= s.size; ++i)
    if (StartsWithPrefix(s.data + i, s.size - i)) return i;
  return s.size;
}

}  // namespace

void ParseBuffer(ByteSpan buffer, std::vector<Packet>* out, ParseStats* stats) {
  size_t pos = 0;
  while (pos < buffer.size) {
    const size_t start = NextPrefix(buffer, pos);
    stats->skipped_bytes += start - pos;
    if (start >= buffer.size) break;
    ByteSpan rest = buffer.Sub(start, buffer.size - start);
    Reader r(rest);
    ByteSpan key_bytes, value;
    uint64_t len = 0;
    if (!r.ReadSpan(16, &key_bytes) || !r.ReadBerLength(&len) || len > r.remaining() ||
        !r.ReadSpan(static_cast<size_t>(len), &value)) {
      // A truncated packet: count it and resynchronise after its prefix.
      ++stats->malformed;
      pos = start + 4;
      continue;
    }
    const ByteSpan whole = rest.Sub(0, r.pos());
    Packet p;
    std::memcpy(p.key.data(), key_bytes.data, 16);
    bool ok = true;
    if (UlEqualIgnoringVersion(p.key, kSt0601Key)) {
      ok = DecodeSt0601Packet(whole, value, &p, stats);
    } else if (UlEqualIgnoringVersion(p.key, kEg0104Key)) {
      ok = DecodeEg0104Packet(value, &p, stats);
    } else if (UlEqualIgnoringVersion(p.key, kSt0102Key)) {
      p.standard = Standard::kSt0102;
      p.name = "MISB ST0102 Local Set";
      ok = DecodeSt0102Items(value, &p.items, stats);
      if (!ok) ++stats->malformed;
    } else {
      p.name = KnownKeyName(p.key);
      Item raw;
      raw.name = "Unparsed";
      raw.parsed = false;
      raw.unparsed.assign(value.data, value.data + value.size);
      p.items.push_back(std::move(raw));
      ++stats->unknown_keys;
    }
    if (ok) {
      out->push_back(std::move(p));
      ++stats->packets;
    }
    pos = start + r.pos();
  }
}

namespace {

nlohmann::json UlJson(const UlKey& k, const std::string& name) {
  return {{"bytes", Base64(ByteSpan(k.data(), k.size()))}, {"hex", UlHex(k)}, {"string", name}};
}

}  // namespace

nlohmann::json ToJson(const Item& item) {
  nlohmann::json j;
  if (item.key)
    j["key"] = UlJson(*item.key, item.name);
  else
    j["key"] = {{"integer", item.tag}, {"string", item.name}};
  j["value"] = item.value;
  if (!item.parsed) j["value-unparsed-bytes"] = Base64(ByteSpan(item.unparsed.data(), item.unparsed.size()));
  return j;
}

nlohmann::json ToJson(const Packet& p) {
  nlohmann::json j;
  j["stream-index"] = p.stream_index;
  j["time"] = p.time_seconds ? nlohmann::json(*p.time_seconds) : nlohmann::json();
  // KWIVER's field: the media time in microseconds.
  j["microseconds"] = p.time_seconds ? nlohmann::json(std::llround(*p.time_seconds * 1e6)) : nlohmann::json();
  j["key"] = UlJson(p.key, p.name);
  nlohmann::json items = nlohmann::json::array();
  for (const auto& it : p.items) items.push_back(ToJson(it));
  j["value"] = std::move(items);
  return j;
}

}  // namespace fmv3d::telemetry::klv
