// 3D Tiles formats (io/tiles3d.h): .pnts written and parsed back byte-exactly, .b3dm framing, GLB bounds.
#include "fmv3d/io/tiles3d.h"

#include <gtest/gtest.h>

#include <cstring>

#include "fmv3d/core/error.h"

namespace fmv3d::io {
namespace {

uint32_t U32(const std::string& s, size_t at) {
  uint32_t v;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}

TEST(Tiles3d, PntsRoundTripAndLayout) {
  PntsTile t;
  t.rtc_center = {1000.5, -20, 3};
  for (int i = 0; i < 37; ++i) {
    t.positions.emplace_back(i * 0.5f, -i * 0.25f, 1.0f + i);
    t.colors.emplace_back(uint8_t(i), uint8_t(255 - i), uint8_t(7 * i));
    t.normals.push_back(Eigen::Vector3f(i, 1, 2).normalized());
    t.views.push_back(static_cast<uint8_t>(3 + i));
  }
  const std::string bytes = EncodePnts(t);
  ASSERT_GE(bytes.size(), 28u);
  EXPECT_EQ(bytes.substr(0, 4), "pnts");
  EXPECT_EQ(U32(bytes, 4), 1u);
  EXPECT_EQ(U32(bytes, 8), bytes.size());
  const uint32_t json_len = U32(bytes, 12), bin_len = U32(bytes, 16), bt_json = U32(bytes, 20), bt_bin = U32(bytes, 24);
  EXPECT_EQ((28 + json_len) % 8, 0u);
  EXPECT_EQ(bin_len % 8, 0u);
  EXPECT_EQ((28 + json_len + bin_len + bt_json) % 8, 0u);
  EXPECT_EQ(bt_bin, 40u);  // 37 bytes padded to 8
  EXPECT_EQ(28 + json_len + bin_len + bt_json + bt_bin, bytes.size());
  const auto bt = nlohmann::json::parse(bytes.substr(28 + json_len + bin_len, bt_json));
  EXPECT_EQ(bt["views"]["componentType"], "UNSIGNED_BYTE");
  EXPECT_GE(bin_len, 37u * (12 + 12 + 3));
  const auto ft = nlohmann::json::parse(bytes.substr(28, json_len));
  EXPECT_EQ(ft["POINTS_LENGTH"], 37);
  EXPECT_EQ(ft["POSITION"]["byteOffset"], 0);
  EXPECT_TRUE(ft.contains("RGB") && ft.contains("NORMAL") && ft.contains("RTC_CENTER"));
  EXPECT_EQ(ft["NORMAL"]["byteOffset"].get<int>() % 4, 0);

  const PntsTile back = DecodePnts(bytes);
  EXPECT_EQ(back.rtc_center, t.rtc_center);
  ASSERT_EQ(back.positions.size(), 37u);
  for (size_t i = 0; i < 37; ++i) {
    EXPECT_EQ(back.positions[i], t.positions[i]);
    EXPECT_EQ(back.colors[i], t.colors[i]);
    EXPECT_EQ(back.normals[i], t.normals[i]);
    EXPECT_EQ(back.views[i], t.views[i]);
  }
  EXPECT_TRUE(back.sigma.empty());
}

TEST(Tiles3d, PntsSigmaInTheBatchTable) {
  PntsTile t;
  for (int i = 0; i < 13; ++i) {
    t.positions.emplace_back(i, 0, 0);
    t.views.push_back(static_cast<uint8_t>(i));
    t.sigma.push_back(0.01f * (i + 1));
  }
  const std::string bytes = EncodePnts(t);
  const uint32_t json_len = U32(bytes, 12), bin_len = U32(bytes, 16), bt_json = U32(bytes, 20), bt_bin = U32(bytes, 24);
  const auto bt = nlohmann::json::parse(bytes.substr(28 + json_len + bin_len, bt_json));
  EXPECT_EQ(bt["sigma"]["componentType"], "FLOAT");
  EXPECT_EQ(bt["sigma"]["type"], "SCALAR");
  EXPECT_EQ(bt["sigma"]["byteOffset"], 16);  // after 13 view bytes padded to 8
  EXPECT_EQ(bt_bin, 16u + 56u);              // 13 floats padded to 8
  const PntsTile back = DecodePnts(bytes);
  ASSERT_EQ(back.sigma.size(), 13u);
  for (int i = 0; i < 13; ++i) EXPECT_EQ(back.sigma[i], t.sigma[i]);
  EXPECT_EQ(back.views, t.views);
  // σ alone: at offset 0.
  t.views.clear();
  const PntsTile only = DecodePnts(EncodePnts(t));
  EXPECT_EQ(only.sigma, t.sigma);
  EXPECT_TRUE(only.views.empty());
  t.sigma.pop_back();
  EXPECT_THROW(EncodePnts(t), Error);
}

TEST(Tiles3d, PntsWithoutOptionalAttributesAndEmpty) {
  PntsTile t;
  t.positions = {{1, 2, 3}};
  const PntsTile back = DecodePnts(EncodePnts(t));
  EXPECT_EQ(back.positions.size(), 1u);
  EXPECT_TRUE(back.colors.empty() && back.normals.empty() && back.views.empty());
  EXPECT_EQ(U32(EncodePnts(t), 20), 0u);  // no batch table without views
  EXPECT_TRUE(DecodePnts(EncodePnts(PntsTile{})).positions.empty());
  t.colors.resize(2);
  EXPECT_THROW(EncodePnts(t), Error);
}

TEST(Tiles3d, DecodeRefusesDamagedTiles) {
  PntsTile t;
  t.positions = {{1, 2, 3}, {4, 5, 6}};
  const std::string good = EncodePnts(t);
  EXPECT_THROW(DecodePnts(good.substr(0, good.size() - 8)), Error);  // byteLength disagrees
  std::string bad = good;
  bad[0] = 'x';
  EXPECT_THROW(DecodePnts(bad), Error);
  bad = good;
  // POINTS_LENGTH larger than the body: rewrite the JSON in place with the same length.
  const std::string json = good.substr(28, U32(good, 12));
  std::string forged = json;
  const size_t at = forged.find("\"POINTS_LENGTH\":2");
  ASSERT_NE(at, std::string::npos);
  forged.replace(at, 17, "\"POINTS_LENGTH\":9");
  bad.replace(28, json.size(), forged);
  EXPECT_THROW(DecodePnts(bad), Error);
  EXPECT_THROW(DecodePnts("pnts"), Error);
}

std::string MinimalGlb() {
  const std::string json =
      R"({"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],)"
      R"("accessors":[{"componentType":5126,"count":3,"type":"VEC3","min":[-1,2,-3],"max":[4,5,6]}]})";
  std::string padded = json;
  padded.append((4 - padded.size() % 4) % 4, ' ');
  std::string glb = "glTF";
  auto put = [&glb](uint32_t v) { glb.append(reinterpret_cast<const char*>(&v), 4); };
  put(2);
  put(static_cast<uint32_t>(12 + 8 + padded.size()));
  put(static_cast<uint32_t>(padded.size()));
  glb += "JSON";
  glb += padded;
  return glb;
}

TEST(Tiles3d, B3dmWrapsTheGlbAndBoundsAreZUp) {
  const std::string glb = MinimalGlb();
  const std::string b3dm = EncodeB3dm(glb);
  EXPECT_EQ(b3dm.substr(0, 4), "b3dm");
  EXPECT_EQ(U32(b3dm, 8), b3dm.size());
  EXPECT_EQ(b3dm.size() % 8, 0u);
  const uint32_t json_len = U32(b3dm, 12);
  EXPECT_EQ((28 + json_len) % 8, 0u);
  EXPECT_EQ(nlohmann::json::parse(b3dm.substr(28, json_len))["BATCH_LENGTH"], 0);
  EXPECT_EQ(b3dm.substr(28 + json_len, glb.size()), glb);
  const Eigen::AlignedBox3d box = GlbBoundsZUp(glb);
  // glTF (x, y, z) -> z-up (x, -z, y): x in [-1, 4], y in [-6, 3], z in [2, 5].
  EXPECT_EQ(box.min(), Eigen::Vector3d(-1, -6, 2));
  EXPECT_EQ(box.max(), Eigen::Vector3d(4, 3, 5));
  EXPECT_THROW(EncodeB3dm("not a glb at all, no"), Error);
}

}  // namespace
}  // namespace fmv3d::io
