// KLV primitives and the ST 0601 / EG0104 / ST 0102 decoders on hand-built byte arrays: BER edge cases,
// mappings and their error values, checksums, truncations, resynchronisation, nested sets.
#include <gtest/gtest.h>

#include <cmath>

#include "fmv3d/telemetry/klv.h"
#include "fmv3d/telemetry/klv_eg0104.h"
#include "fmv3d/telemetry/klv_st0102.h"
#include "fmv3d/telemetry/klv_st0601.h"
#include "klv_test_bytes.h"

namespace fmv3d::telemetry::klv {
namespace {

using test::Append;
using test::BigEndian;
using test::Bytes;
using test::St0601Packet;
using test::Str;
using test::Tlv;

std::vector<Packet> Parse(const Bytes& b, ParseStats* stats) {
  std::vector<Packet> out;
  ParseBuffer(ByteSpan(b.data(), b.size()), &out, stats);
  return out;
}

TEST(KlvBer, ShortAndLongForms) {
  const Bytes b = {0x05, 0x81, 0xC8, 0x82, 0x01, 0x00, 0x84, 0x00, 0x00, 0x00, 0x7F, 0x80};
  Reader r(ByteSpan(b.data(), b.size()));
  uint64_t v = 0;
  ASSERT_TRUE(r.ReadBerLength(&v));
  EXPECT_EQ(v, 5u);
  ASSERT_TRUE(r.ReadBerLength(&v));
  EXPECT_EQ(v, 200u);
  ASSERT_TRUE(r.ReadBerLength(&v));
  EXPECT_EQ(v, 256u);
  ASSERT_TRUE(r.ReadBerLength(&v));  // long form with leading zero bytes is legal
  EXPECT_EQ(v, 127u);
  EXPECT_FALSE(r.ReadBerLength(&v));  // 0x80 = indefinite form, forbidden by MISB
}

TEST(KlvBer, TruncatedLongFormFailsWithoutMoving) {
  const Bytes b = {0x83, 0x01, 0x02};
  Reader r(ByteSpan(b.data(), b.size()));
  uint64_t v = 0;
  EXPECT_FALSE(r.ReadBerLength(&v));
  EXPECT_EQ(r.pos(), 0u);
  const Bytes nine = {0x89, 1, 2, 3, 4, 5, 6, 7, 8, 9};  // more than 8 length bytes
  Reader r2(ByteSpan(nine.data(), nine.size()));
  EXPECT_FALSE(r2.ReadBerLength(&v));
}

TEST(KlvBer, OidTags) {
  const Bytes b = {0x7F, 0x81, 0x01, 0x82, 0x80, 0x00, 0x81};
  Reader r(ByteSpan(b.data(), b.size()));
  uint64_t v = 0;
  ASSERT_TRUE(r.ReadBerOid(&v));
  EXPECT_EQ(v, 127u);
  ASSERT_TRUE(r.ReadBerOid(&v));
  EXPECT_EQ(v, 129u);
  ASSERT_TRUE(r.ReadBerOid(&v));
  EXPECT_EQ(v, 32768u);
  EXPECT_FALSE(r.ReadBerOid(&v));  // continuation bit set on the last byte
}

TEST(KlvMapping, St0601ExampleValues) {
  // Encodings and decimal values from the ST 0601 example packet.
  EXPECT_NEAR(MapUnsigned(0x71C2, 2, 0, 360), 159.9744, 1e-4);
  EXPECT_NEAR(*MapSigned(0x5595B66D, 4, 90), 60.176822966978335, 1e-12);
  EXPECT_NEAR(*MapSigned(ReadIntBE(ByteSpan(Bytes{0x87, 0xF8, 0x4B, 0x86}.data(), 4)), 4, 180), -168.79232483394085,
              1e-12);
  EXPECT_NEAR(MapUnsigned(0xC221, 2, -900, 19000), 14190.72, 0.01);
  // The reserved most-negative value means "error / N/A".
  EXPECT_FALSE(MapSigned(ReadIntBE(ByteSpan(Bytes{0x80, 0x00, 0x00, 0x00}.data(), 4)), 4, 90).has_value());
  EXPECT_FALSE(MapSigned(ReadIntBE(ByteSpan(Bytes{0x80, 0x00}.data(), 2)), 2, 20).has_value());
  // The extremes map to the range ends.
  EXPECT_DOUBLE_EQ(*MapSigned(ReadIntBE(ByteSpan(Bytes{0x80, 0x01}.data(), 2)), 2, 20), -20.0);
  EXPECT_DOUBLE_EQ(*MapSigned(0x7FFF, 2, 20), 20.0);
  EXPECT_DOUBLE_EQ(MapUnsigned(0xFFFF, 2, -900, 19000), 19000.0);
}

TEST(KlvMapping, ImapbMatchesSt1201) {
  const auto dec = [](const Bytes& b, double a, double c) { return DecodeImapb(ByteSpan(b.data(), b.size()), a, c); };
  // klv_gold.json: Density Altitude Extended (tag 103), length 3, value 1000.0 = (1000 + 900) * 2^7.
  EXPECT_DOUBLE_EQ(*dec({0x03, 0xB6, 0x00}, -900, 40000), 1000.0);
  // ST 0601 example values.
  EXPECT_DOUBLE_EQ(*dec({0x2F, 0x92, 0x1E}, -900, 40000), 23456.234375);
  EXPECT_DOUBLE_EQ(*dec({0x1F, 0x40}, 0, 360), 125.0);
  EXPECT_DOUBLE_EQ(*dec({0x3E, 0x80, 0x11}, -1000, 1000), 0.004150390625);
  EXPECT_DOUBLE_EQ(*dec({0x02, 0x57, 0xC0}, 1, 99999), 2400.0);
  // Special values (ST 1201: +inf 0xC8.., -inf 0xE8.., NaNs 0xD0/0xF0..) decode to nothing.
  EXPECT_FALSE(dec({0xC8, 0x00, 0x00}, -900, 40000).has_value());
  EXPECT_FALSE(dec({0xE8, 0x00}, 0, 360).has_value());
  EXPECT_FALSE(dec({0xD0, 0x00}, 0, 360).has_value());
  EXPECT_FALSE(dec({}, 0, 360).has_value());
}

TEST(KlvChecksum, St0601ExampleAndCrc) {
  // CRC-16-CCITT (0xFFFF init) check value of "123456789" is 0x29B1.
  const Bytes digits = Str("123456789");
  EXPECT_EQ(Crc16Ccitt(ByteSpan(digits.data(), digits.size())), 0x29B1);
  const Bytes pkt = St0601Packet({Tlv(2, BigEndian(1224807209913000ull, 8))});
  ParseStats stats;
  const auto packets = Parse(pkt, &stats);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_EQ(stats.bad_checksum, 0u);
  EXPECT_EQ(packets[0].Find(2)->value.get<uint64_t>(), 1224807209913000ull);
}

TEST(KlvSt0601, BadChecksumIsCountedAndSkipped) {
  Bytes buf = St0601Packet({Tlv(13, BigEndian(0x5595B66D, 4))}, /*corrupt=*/true);
  Append(&buf, St0601Packet({Tlv(13, BigEndian(0x5595B66D, 4))}));
  ParseStats stats;
  const auto packets = Parse(buf, &stats);
  EXPECT_EQ(stats.bad_checksum, 1u);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_NEAR(packets[0].Find(kTagSensorLatitude)->value.get<double>(), 60.176822966978335, 1e-12);
}

TEST(KlvSt0601, MissingChecksumIsRejected) {
  Bytes set = Tlv(13, BigEndian(0x5595B66D, 4));
  Bytes buf = test::KeyBytes(kSt0601Key);
  Append(&buf, test::Ber(set.size()));
  Append(&buf, set);
  ParseStats stats;
  EXPECT_TRUE(Parse(buf, &stats).empty());
  EXPECT_EQ(stats.bad_checksum, 1u);
}

TEST(KlvSt0601, TruncationsNeverCrashAndAreCounted) {
  const Bytes full =
      St0601Packet({Tlv(3, Str("MISSION01")), Tlv(13, BigEndian(0x5595B66D, 4)), Tlv(14, BigEndian(0x5B5360C4, 4))});
  for (size_t n = 0; n < full.size(); ++n) {
    ParseStats stats;
    const auto packets = Parse(Bytes(full.begin(), full.begin() + static_cast<long>(n)), &stats);
    EXPECT_TRUE(packets.empty()) << n;
    if (n >= 4) EXPECT_EQ(stats.malformed + stats.bad_checksum, 1u) << n;
  }
}

TEST(KlvSt0601, InnerLengthOverrunIsMalformed) {
  // A local-set item claims 10 bytes but the set ends after 4: the packet is skipped.
  Bytes set = {13, 10, 0x55, 0x95, 0xB6, 0x6D};
  Bytes buf = test::KeyBytes(kSt0601Key);
  Append(&buf, test::Ber(set.size()));
  Append(&buf, set);
  Append(&buf, St0601Packet({Tlv(5, BigEndian(0x71C2, 2))}));
  ParseStats stats;
  const auto packets = Parse(buf, &stats);
  EXPECT_EQ(stats.malformed, 1u);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_NEAR(packets[0].Find(kTagPlatformHeading)->value.get<double>(), 159.9744, 1e-4);
}

TEST(KlvSt0601, ResynchronisesAfterGarbage) {
  Bytes buf = {0x00, 0x47, 0x11, 0x06, 0x0E};  // junk, including a partial prefix
  Append(&buf, St0601Packet({Tlv(5, BigEndian(0x71C2, 2))}));
  ParseStats stats;
  EXPECT_EQ(Parse(buf, &stats).size(), 1u);
  EXPECT_EQ(stats.skipped_bytes, 5u);
}

TEST(KlvSt0601, ErrorValuesUnknownTagsWrongLengthsAndStrings) {
  const Bytes pkt = St0601Packet({
      Tlv(13, {0x80, 0x00, 0x00, 0x00}),             // latitude "N/A (off-earth)"
      Tlv(6, {0x80, 0x00}),                          // pitch error value
      Tlv(5, {0x71}),                                // heading with a wrong length
      Tlv(3, Str(std::string("TEST\0STRING", 11))),  // klv_gold.json keeps the NUL
      Tlv(4, {0x00, 0xFF}),                          // invalid UTF-8: kept as bytes ("AP8=" in the gold)
      Tlv(120, {0x48, 0x00}),                        // IMAPB percent full 72 %
      Tlv(63, {0x02}),                               // enum: Medium
  });
  ParseStats stats;
  const auto packets = Parse(pkt, &stats);
  ASSERT_EQ(packets.size(), 1u);
  const Packet& p = packets[0];
  EXPECT_TRUE(p.Find(13)->value.is_null());
  EXPECT_TRUE(p.Find(13)->parsed);
  EXPECT_TRUE(p.Find(6)->value.is_null());
  EXPECT_FALSE(p.Find(5)->parsed);
  EXPECT_EQ(p.Find(3)->value.get<std::string>(), std::string("TEST\0STRING", 11));
  EXPECT_FALSE(p.Find(4)->parsed);
  EXPECT_EQ(ToJson(*p.Find(4))["value-unparsed-bytes"], "AP8=");
  EXPECT_DOUBLE_EQ(p.Find(120)->value.get<double>(), 72.0);
  EXPECT_EQ(p.Find(63)->value["string"], "Medium");
  EXPECT_EQ(stats.bad_items, 2u);  // tag 5 (length) and tag 4 (UTF-8)
}

TEST(KlvSt0601, UnknownMultiByteTagIsPreserved) {
  // Tag 200 needs a two-byte BER-OID (0x81 0x48); it is not in the dictionary.
  Bytes item = {0x81, 0x48, 0x02, 0xAB, 0xCD};
  const Bytes pkt = St0601Packet({item, Tlv(5, BigEndian(0x71C2, 2))});
  ParseStats stats;
  const auto packets = Parse(pkt, &stats);
  ASSERT_EQ(packets.size(), 1u);
  const Item* it = packets[0].Find(200);
  ASSERT_NE(it, nullptr);
  EXPECT_FALSE(it->parsed);
  EXPECT_EQ(it->unparsed, (Bytes{0xAB, 0xCD}));
  EXPECT_NE(packets[0].Find(kTagPlatformHeading), nullptr);
}

TEST(KlvSt0601, NestedSecuritySetAndSegments) {
  const Bytes security = Tlv(1, {0x01});
  Bytes sec2 = security;
  Append(&sec2, Tlv(2, {0x0D}));
  Append(&sec2, Tlv(13, {0x00, 'U', 0x00, 'S'}));  // UTF-16BE object country code
  Bytes segment = Tlv(13, BigEndian(0x5595B66D, 4));
  const Bytes pkt = St0601Packet({Tlv(48, sec2), Tlv(100, segment), Tlv(101, {0x05, 0x05})});
  ParseStats stats;
  const auto packets = Parse(pkt, &stats);
  ASSERT_EQ(packets.size(), 1u);
  const auto& sec = packets[0].Find(48)->value;
  ASSERT_TRUE(sec.is_array());
  ASSERT_EQ(sec.size(), 3u);
  EXPECT_EQ(sec[0]["value"]["string"], "Unclassified");
  EXPECT_EQ(sec[1]["value"]["string"], "GENC Two Letter");
  EXPECT_EQ(sec[2]["value"], "US");
  const auto& seg = packets[0].Find(100)->value;
  ASSERT_EQ(seg.size(), 1u);
  EXPECT_NEAR(seg[0]["value"].get<double>(), 60.176822966978335, 1e-12);
  // Tag 101 holds a malformed set (an item claiming 5 bytes of 1): kept raw, packet kept.
  EXPECT_FALSE(packets[0].Find(101)->parsed);
}

TEST(KlvSt0601, DeeplyNestedSegmentsStopAtTheDepthLimit) {
  Bytes inner = Tlv(5, BigEndian(0x71C2, 2));
  for (int i = 0; i < 50; ++i) inner = Tlv(100, inner);
  ParseStats stats;
  const auto packets = Parse(St0601Packet({inner}), &stats);
  ASSERT_EQ(packets.size(), 1u);  // no stack overflow, packet kept with the deep part as raw bytes
}

TEST(KlvEg0104, UniversalSetWithGoldKeys) {
  // klv_gold.json's ST 0104 packet: Device Designation "Bob", Episode Number "4.2", timestamp 4321.
  Bytes set;
  auto add = [&](const UlKey& key, const Bytes& v) {
    Append(&set, test::KeyBytes(key));
    Append(&set, test::Ber(v.size()));
    Append(&set, v);
  };
  add(Eg0104KeyOf(Eg0104Field::kDeviceDesignation), Str("Bob"));
  add(Eg0104KeyOf(Eg0104Field::kEpisodeNumber), Str("4.2"));
  add(Eg0104KeyOf(Eg0104Field::kUserDefinedTimestamp), BigEndian(4321, 8));
  add(Eg0104KeyOf(Eg0104Field::kDeviceLatitude), BigEndian(0x404314789613d31cull, 8));
  add(Eg0104KeyOf(Eg0104Field::kHorizontalFov), {0x3F, 0x4C, 0xCC, 0xCD});
  add(Eg0104KeyOf(Eg0104Field::kVerticalFov), {0x3F, 0x4C});  // wrong length: kept raw
  Bytes buf = test::KeyBytes(kEg0104Key);
  Append(&buf, test::Ber(set.size()));
  Append(&buf, set);
  ParseStats stats;
  const auto packets = Parse(buf, &stats);
  ASSERT_EQ(packets.size(), 1u);
  const nlohmann::json j = ToJson(packets[0]);
  EXPECT_EQ(j["key"]["string"], "MISB ST0104 Universal Set");
  EXPECT_EQ(j["key"]["hex"], "060e2b34 02010101 0e010102 01010000");
  EXPECT_EQ(j["value"][0]["key"]["string"], "Device Designation");
  EXPECT_EQ(j["value"][0]["value"], "Bob");
  EXPECT_EQ(j["value"][1]["value"], "4.2");
  EXPECT_EQ(j["value"][2]["key"]["string"], "User Defined Timestamp");
  EXPECT_EQ(j["value"][2]["value"], 4321);
  EXPECT_NEAR(j["value"][3]["value"].get<double>(), 38.15993, 1e-9);
  EXPECT_NEAR(j["value"][4]["value"].get<double>(), 0.8, 1e-7);
  EXPECT_FALSE(packets[0].items[5].parsed);
  EXPECT_EQ(stats.bad_items, 1u);
}

TEST(KlvEg0104, VersionByteIsIgnoredAndTruncatedSetIsMalformed) {
  UlKey k = Eg0104KeyOf(Eg0104Field::kDeviceLongitude);
  k[7] = 0x0F;
  EXPECT_EQ(Eg0104FieldOf(k), Eg0104Field::kDeviceLongitude);
  Bytes set = test::KeyBytes(k);
  Append(&set, {0x08, 0xC0, 0x53});  // claims 8 bytes, has 2
  Bytes buf = test::KeyBytes(kEg0104Key);
  Append(&buf, test::Ber(set.size()));
  Append(&buf, set);
  ParseStats stats;
  EXPECT_TRUE(Parse(buf, &stats).empty());
  EXPECT_EQ(stats.malformed, 1u);
}

TEST(KlvSt0102, StandalonePacketMatchesGold) {
  Bytes set = Tlv(1, {0x01});
  Append(&set, Tlv(2, {0x0D}));
  Bytes buf = test::KeyBytes(kSt0102Key);
  Append(&buf, test::Ber(set.size()));
  Append(&buf, set);
  ParseStats stats;
  const auto packets = Parse(buf, &stats);
  ASSERT_EQ(packets.size(), 1u);
  const nlohmann::json j = ToJson(packets[0]);
  EXPECT_EQ(j["key"]["string"], "MISB ST0102 Local Set");
  EXPECT_EQ(j["key"]["bytes"], "Bg4rNAIDAQEOAQMDAgAAAA==");
  EXPECT_EQ(j["value"][0]["value"], (nlohmann::json{{"integer", 1}, {"string", "Unclassified"}}));
  EXPECT_EQ(j["value"][1]["value"], (nlohmann::json{{"integer", 13}, {"string", "GENC Two Letter"}}));
}

TEST(KlvUnknownKey, KeptRawAndCounted) {
  Bytes buf = {0x06, 0x0E, 0x2B, 0x34, 0x02, 0x0B, 0x01, 0x01, 0x0E, 0x01, 0x03, 0x03, 0x22, 0x00, 0x00, 0x00};
  Append(&buf, {0x03, 0x26, 0x01, 0x02});
  ParseStats stats;
  const auto packets = Parse(buf, &stats);
  ASSERT_EQ(packets.size(), 1u);
  EXPECT_EQ(packets[0].name, "MISB ST1107 Local Set");
  EXPECT_EQ(stats.unknown_keys, 1u);
  EXPECT_EQ(ToJson(packets[0])["value"][0]["value-unparsed-bytes"], "JgEC");
}

}  // namespace
}  // namespace fmv3d::telemetry::klv
