// KLV (SMPTE 336 key-length-value) primitives shared by the MISB parsers: a bounds-checked byte reader, BER
// lengths and BER-OID tags, 16-byte universal label keys, the ST 0601 checksum, the int-mapped encodings
// (ST 0601 scaled integers, ST 1201 IMAPB) and the decoded-packet model that `fmv3d klv` dumps as JSON.
//
// Every function here takes untrusted bytes: nothing reads past the span it is given, and malformed input is
// reported by a false/nullopt return, never by a crash or an exception.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::telemetry::klv {

// A non-owning view of bytes (C++17 has no std::span).
struct ByteSpan {
  const uint8_t* data = nullptr;
  size_t size = 0;
  ByteSpan() = default;
  ByteSpan(const uint8_t* d, size_t n) : data(d), size(n) {}
  explicit ByteSpan(const std::vector<uint8_t>& v) : data(v.data()), size(v.size()) {}
  ByteSpan Sub(size_t offset, size_t n) const { return {data + offset, n}; }
};

// Sequential reader; every Read* returns false (and leaves the position unchanged) when the bytes run out.
class Reader {
 public:
  explicit Reader(ByteSpan s) : s_(s) {}
  size_t pos() const { return pos_; }
  size_t remaining() const { return s_.size - pos_; }
  bool empty() const { return pos_ >= s_.size; }
  bool ReadByte(uint8_t* b);
  bool ReadSpan(size_t n, ByteSpan* out);
  // BER length: short form (< 128) or long form (0x8N followed by N big-endian bytes, N <= 8). The
  // indefinite form (0x80) is rejected, as MISB forbids it.
  bool ReadBerLength(uint64_t* len);
  // BER-OID: 7 bits per byte, high bit set on all but the last byte (local-set tags); at most 9 bytes.
  bool ReadBerOid(uint64_t* value);

 private:
  ByteSpan s_;
  size_t pos_ = 0;
};

// Big-endian integer of 1..8 bytes; signed variant sign-extends from the top bit of the first byte.
uint64_t ReadUintBE(ByteSpan s);
int64_t ReadIntBE(ByteSpan s);

// MISB ST 0601 checksum: a running 16-bit sum over the whole packet (16-byte key, BER length and the
// local set up to and including the checksum tag and length bytes), even-index bytes in the high byte.
uint16_t St0601Checksum(ByteSpan s);
// CRC-16-CCITT (poly 0x1021, init 0xFFFF, no reflection), the checksum of several later MISB sets
// (e.g. ST 1108, ST 0903 in some versions); offered for them and for tests.
uint16_t Crc16Ccitt(ByteSpan s);

// ST 0601 unsigned mapping: [0, 2^(8n)-1] -> [lo, hi].
double MapUnsigned(uint64_t v, size_t n, double lo, double hi);
// ST 0601 signed mapping: [-(2^(8n-1)-1), 2^(8n-1)-1] -> [-range, range]; the most negative value
// (0x80.., "reserved/error", e.g. "N/A (off-earth)") decodes to nullopt.
std::optional<double> MapSigned(int64_t v, size_t n, double range);
// ST 1201 IMAPB(a, b, n) inverse: the value, or nullopt for the special encodings (+/-infinity, NaNs,
// user-defined, out of range) that the standard reserves in the upper half of the code space.
std::optional<double> DecodeImapb(ByteSpan s, double a, double b);

// A 16-byte SMPTE universal label.
using UlKey = std::array<uint8_t, 16>;
std::string UlHex(const UlKey& k);  // "060e2b34 020b0101 0e010301 01000000" (KWIVER's layout)
// Compares two labels ignoring byte 7 (the registry version byte), as MISB readers must.
bool UlEqualIgnoringVersion(const UlKey& a, const UlKey& b);
std::string Base64(ByteSpan s);
// The name of a known top-level key ("MISB ST0601 Local Set", ...) or "Unknown".
std::string KnownKeyName(const UlKey& k);

// One decoded item of a set: a local-set tag or a universal-set key, its name, its decoded value (number,
// string, enum {"integer","string"}, nested item list; null for an error/"N/A" encoding) and, when the value
// could not be decoded (unknown tag, unexpected length, opaque sub-standard), its raw bytes.
struct Item {
  uint64_t tag = 0;          // local-set tag (0 for universal-set items)
  std::optional<UlKey> key;  // universal-set key
  std::string name;
  nlohmann::json value;           // null when absent/error/unparsed
  std::vector<uint8_t> unparsed;  // raw bytes kept when `value` could not be decoded
  bool parsed = true;
};

enum class Standard { kUnknown, kSt0601, kEg0104, kSt0102 };

struct Packet {
  UlKey key{};
  Standard standard = Standard::kUnknown;
  std::string name;  // "MISB ST0601 Local Set", ...
  std::vector<Item> items;
  int stream_index = -1;               // container stream, -1 for a raw buffer
  std::optional<double> time_seconds;  // presentation time in the container, when known
  // Finds the first item with this local-set tag / universal key (nullptr if absent).
  const Item* Find(uint64_t tag) const;
  const Item* Find(const UlKey& key) const;
};

struct ParseStats {
  size_t packets = 0;        // packets decoded and kept
  size_t bad_checksum = 0;   // ST 0601 packets whose checksum did not match (skipped)
  size_t malformed = 0;      // truncated / inconsistent packets (skipped)
  size_t unknown_keys = 0;   // top-level packets of an unrecognised standard (kept, undecoded)
  size_t bad_items = 0;      // items whose length did not fit their type (kept as raw bytes)
  size_t skipped_bytes = 0;  // bytes skipped while resynchronising on the KLV key prefix
  void Add(const ParseStats& o);
};

// Splits a buffer (e.g. one demuxed KLV access unit) into top-level KLV packets, decodes the known ones
// (ST 0601, EG0104, ST 0102) and appends them to `out`. Never throws on malformed bytes.
void ParseBuffer(ByteSpan buffer, std::vector<Packet>* out, ParseStats* stats);

// JSON close to KWIVER's klv_gold.json layout: {"stream-index", "time", "key": {bytes,hex,string},
// "value": [ {"key": {integer,string} | {bytes,hex,string}, "value": ..., ["value-unparsed-bytes": b64]} ]}.
nlohmann::json ToJson(const Packet& p);
nlohmann::json ToJson(const Item& item);

// Internal to the set parsers: parses a local set into (tag, bytes) pairs; false if a length overruns.
struct RawLocalItem {
  uint64_t tag = 0;
  ByteSpan value;
  size_t offset = 0;  // offset of the tag's first byte within the set
};
bool SplitLocalSet(ByteSpan set, std::vector<RawLocalItem>* items);

}  // namespace fmv3d::telemetry::klv
