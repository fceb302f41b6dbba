#include "fmv3d/io/tiles3d.h"

#include <cstring>

#include "fmv3d/core/error.h"

namespace fmv3d::io {

namespace {
constexpr size_t kHeader = 28;

void PutU32(std::string* s, uint32_t v) {
  char b[4];
  std::memcpy(b, &v, 4);  // little-endian hosts only (x86-64, arm64)
  s->append(b, 4);
}
uint32_t GetU32(const std::string& s, size_t at) {
  uint32_t v = 0;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}
size_t Pad8(size_t n) { return (n + 7) & ~size_t{7}; }

// The feature table JSON padded with spaces so that the header + JSON ends on 8 bytes.
std::string PaddedJson(const nlohmann::json& j, size_t start) {
  std::string text = j.dump();
  text.append(Pad8(start + text.size()) - start - text.size(), ' ');
  return text;
}

// The batch table binary `bt_bin` is counted in the header; `body` (a b3dm's GLB) follows it uncounted.
std::string Assemble(const char magic[4], const std::string& ft_json, const std::string& ft_bin,
                     const std::string& bt_json, const std::string& bt_bin, const std::string& body) {
  std::string out(magic, 4);
  PutU32(&out, 1);
  PutU32(&out, static_cast<uint32_t>(kHeader + ft_json.size() + ft_bin.size() + bt_json.size() + bt_bin.size() +
                                     body.size()));
  PutU32(&out, static_cast<uint32_t>(ft_json.size()));
  PutU32(&out, static_cast<uint32_t>(ft_bin.size()));
  PutU32(&out, static_cast<uint32_t>(bt_json.size()));
  PutU32(&out, static_cast<uint32_t>(bt_bin.size()));
  return out + ft_json + ft_bin + bt_json + bt_bin + body;
}
}  // namespace

std::string EncodePnts(const PntsTile& t) {
  const size_t n = t.positions.size();
  if ((!t.colors.empty() && t.colors.size() != n) || (!t.normals.empty() && t.normals.size() != n) ||
      (!t.views.empty() && t.views.size() != n) || (!t.sigma.empty() && t.sigma.size() != n))
    throw Error("EncodePnts: attribute sizes differ from the point count");
  std::string bin;
  nlohmann::json ft = {{"POINTS_LENGTH", n},
                       {"RTC_CENTER", {t.rtc_center.x(), t.rtc_center.y(), t.rtc_center.z()}},
                       {"POSITION", {{"byteOffset", 0}}}};
  bin.append(reinterpret_cast<const char*>(t.positions.data()), n * 12);
  if (!t.normals.empty()) {
    ft["NORMAL"] = {{"byteOffset", bin.size()}};
    bin.append(reinterpret_cast<const char*>(t.normals.data()), n * 12);
  }
  if (!t.colors.empty()) {
    ft["RGB"] = {{"byteOffset", bin.size()}};
    bin.append(reinterpret_cast<const char*>(t.colors.data()), n * 3);
  }
  bin.append(Pad8(bin.size()) - bin.size(), '\0');
  const std::string ft_json = PaddedJson(ft, kHeader);
  if (t.views.empty() && t.sigma.empty()) return Assemble("pnts", ft_json, bin, "", "", "");
  nlohmann::json bt = nlohmann::json::object();
  std::string bt_bin;
  if (!t.views.empty()) {
    bt["views"] = {{"byteOffset", 0}, {"componentType", "UNSIGNED_BYTE"}, {"type", "SCALAR"}};
    bt_bin.assign(t.views.begin(), t.views.end());
    bt_bin.append(Pad8(bt_bin.size()) - bt_bin.size(), '\0');
  }
  if (!t.sigma.empty()) {
    bt["sigma"] = {{"byteOffset", bt_bin.size()}, {"componentType", "FLOAT"}, {"type", "SCALAR"}};
    bt_bin.append(reinterpret_cast<const char*>(t.sigma.data()), n * 4);
    bt_bin.append(Pad8(bt_bin.size()) - bt_bin.size(), '\0');
  }
  const std::string bt_json = PaddedJson(bt, kHeader + ft_json.size() + bin.size());
  return Assemble("pnts", ft_json, bin, bt_json, bt_bin, "");
}

PntsTile DecodePnts(const std::string& bytes) {
  if (bytes.size() < kHeader || bytes.compare(0, 4, "pnts") != 0) throw Error("pnts: no 'pnts' header");
  if (GetU32(bytes, 4) != 1) throw Error("pnts: version is not 1");
  const size_t length = GetU32(bytes, 8), ft_json = GetU32(bytes, 12), ft_bin = GetU32(bytes, 16),
               bt_json = GetU32(bytes, 20), bt_bin = GetU32(bytes, 24);
  if (length != bytes.size()) throw Error("pnts: byteLength differs from the file size");
  if (kHeader + ft_json + ft_bin + bt_json + bt_bin != length) throw Error("pnts: section lengths do not add up");
  if ((kHeader + ft_json) % 8 != 0 || ft_bin % 8 != 0) throw Error("pnts: sections not padded to 8 bytes");
  const nlohmann::json ft =
      nlohmann::json::parse(bytes.begin() + kHeader, bytes.begin() + kHeader + ft_json, nullptr, false);
  if (ft.is_discarded() || !ft.is_object() || !ft.contains("POINTS_LENGTH") ||
      !ft["POINTS_LENGTH"].is_number_unsigned())
    throw Error("pnts: feature table JSON without POINTS_LENGTH");
  for (const char* unsupported : {"POSITION_QUANTIZED", "NORMAL_OCT16P", "RGBA", "RGB565", "BATCH_ID"})
    if (ft.contains(unsupported)) throw Error(std::string("pnts: ") + unsupported + " is not read here");
  const size_t n = ft["POINTS_LENGTH"].get<size_t>();
  const char* bin = bytes.data() + kHeader + ft_json;
  auto section = [&](const char* name, size_t item) -> const char* {
    if (!ft.contains(name)) return nullptr;
    const auto& s = ft[name];
    if (!s.is_object() || !s.contains("byteOffset") || !s["byteOffset"].is_number_unsigned())
      throw Error(std::string("pnts: ") + name + " without byteOffset");
    const size_t off = s["byteOffset"].get<size_t>();
    if (n > ft_bin / item || off > ft_bin - n * item) throw Error(std::string("pnts: ") + name + " out of range");
    return bin + off;
  };
  PntsTile t;
  const char* pos = section("POSITION", 12);
  if (!pos) throw Error("pnts: no POSITION");
  t.positions.resize(n);
  if (n > 0) std::memcpy(static_cast<void*>(t.positions.data()), pos, n * 12);  // an empty vector's data() may be null
  if (const char* nor = section("NORMAL", 12)) {
    t.normals.resize(n);
    if (n > 0) std::memcpy(static_cast<void*>(t.normals.data()), nor, n * 12);
  }
  if (const char* rgb = section("RGB", 3)) {
    t.colors.resize(n);
    if (n > 0) std::memcpy(static_cast<void*>(t.colors.data()), rgb, n * 3);
  }
  if (bt_json > 0) {
    const size_t bt_at = kHeader + ft_json + ft_bin;
    const nlohmann::json bt =
        nlohmann::json::parse(bytes.begin() + bt_at, bytes.begin() + bt_at + bt_json, nullptr, false);
    if (bt.is_discarded() || !bt.is_object()) throw Error("pnts: malformed batch table JSON");
    if (bt.contains("views")) {
      const auto& v = bt["views"];
      if (!v.is_object() || v.value("componentType", "") != "UNSIGNED_BYTE" || !v.contains("byteOffset") ||
          !v["byteOffset"].is_number_unsigned())
        throw Error("pnts: batch table 'views' is not an UNSIGNED_BYTE reference");
      const size_t off = v["byteOffset"].get<size_t>();
      if (off > bt_bin || n > bt_bin - off) throw Error("pnts: batch table 'views' out of range");
      const char* p = bytes.data() + bt_at + bt_json + off;
      t.views.assign(reinterpret_cast<const uint8_t*>(p), reinterpret_cast<const uint8_t*>(p) + n);
    }
    if (bt.contains("sigma")) {
      const auto& v = bt["sigma"];
      if (!v.is_object() || v.value("componentType", "") != "FLOAT" || !v.contains("byteOffset") ||
          !v["byteOffset"].is_number_unsigned())
        throw Error("pnts: batch table 'sigma' is not a FLOAT reference");
      const size_t off = v["byteOffset"].get<size_t>();
      if (off > bt_bin || n > (bt_bin - off) / 4) throw Error("pnts: batch table 'sigma' out of range");
      t.sigma.resize(n);
      if (n > 0) std::memcpy(t.sigma.data(), bytes.data() + bt_at + bt_json + off, n * 4);
    }
  }
  if (ft.contains("RTC_CENTER")) {
    const auto& c = ft["RTC_CENTER"];
    if (!c.is_array() || c.size() != 3 || !c[0].is_number() || !c[1].is_number() || !c[2].is_number())
      throw Error("pnts: RTC_CENTER is not 3 numbers");
    t.rtc_center = {c[0].get<double>(), c[1].get<double>(), c[2].get<double>()};
  }
  return t;
}

namespace {
// The JSON chunk of a GLB (header: magic "glTF", version 2, length; chunk 0: length, type "JSON").
nlohmann::json GlbJson(const std::string& glb) {
  if (glb.size() < 20 || glb.compare(0, 4, "glTF") != 0) throw Error("glb: no 'glTF' header");
  const size_t chunk = GetU32(glb, 12);
  if (glb.compare(16, 4, "JSON") != 0 || 20 + chunk > glb.size()) throw Error("glb: no JSON chunk");
  nlohmann::json j = nlohmann::json::parse(glb.begin() + 20, glb.begin() + 20 + chunk, nullptr, false);
  if (j.is_discarded()) throw Error("glb: malformed JSON chunk");
  return j;
}
}  // namespace

std::string EncodeB3dm(const std::string& glb) {
  GlbJson(glb);
  std::string body = glb;
  body.append(Pad8(body.size()) - body.size(), '\0');  // b3dm ends on 8 bytes; GLB readers use their own length
  return Assemble("b3dm", PaddedJson({{"BATCH_LENGTH", 0}}, kHeader), "", "", "", body);
}

Eigen::AlignedBox3d GlbBoundsZUp(const std::string& glb) {
  const nlohmann::json j = GlbJson(glb);
  Eigen::AlignedBox3d box;
  try {
    for (const auto& mesh : j.value("meshes", nlohmann::json::array()))
      for (const auto& prim : mesh.at("primitives")) {
        const auto& acc = j.at("accessors").at(prim.at("attributes").at("POSITION").get<size_t>());
        const auto& mn = acc.at("min");
        const auto& mx = acc.at("max");
        for (const auto* v : {&mn, &mx}) {
          const double x = v->at(0).get<double>(), y = v->at(1).get<double>(), z = v->at(2).get<double>();
          box.extend(Eigen::Vector3d(x, -z, y));
        }
      }
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("glb: POSITION accessors without min/max (") + e.what() + ")");
  }
  if (box.isEmpty()) throw Error("glb: no mesh positions");
  return box;
}

nlohmann::json BoxVolume(const Eigen::AlignedBox3d& box) {
  const Eigen::Vector3d c = box.center();
  // A flat or single-point box still gets a non-zero extent (clients divide by it).
  const Eigen::Vector3d h = (0.5 * box.sizes()).cwiseMax(1e-3);
  return {{"box", {c.x(), c.y(), c.z(), h.x(), 0, 0, 0, h.y(), 0, 0, 0, h.z()}}};
}

}  // namespace fmv3d::io
