#include "fmv3d/geo/las.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

namespace {

constexpr uint16_t kHeaderSize = 375;

// The header's creation day: the clock's, or SOURCE_DATE_EPOCH's (seconds since 1970, the reproducible-builds
// convention) when it holds a valid one, so that two runs of one workspace can write the same bytes.
std::time_t CreationTime() {
  if (const char* e = std::getenv("SOURCE_DATE_EPOCH")) {
    char* end = nullptr;
    const long long t = std::strtoll(e, &end, 10);
    if (end != e && *end == '\0' && t >= 0 && t < 253402300800LL) return static_cast<std::time_t>(t);  // < year 10000
  }
  return std::time(nullptr);
}
constexpr uint16_t kVlrHeaderSize = 54;
constexpr uint8_t kFormat = 7;
constexpr uint16_t kRecordLength = 36;

class Buf {
 public:
  template <typename T>
  void Put(T v) {
    const size_t at = b_.size();
    b_.resize(at + sizeof(T));
    std::memcpy(b_.data() + at, &v, sizeof(T));  // LAS is little-endian, as is every platform we build on
  }
  void PutString(const std::string& s, size_t n) {
    for (size_t i = 0; i < n; ++i) b_.push_back(i < s.size() ? static_cast<uint8_t>(s[i]) : 0);
  }
  void PutBytes(const std::string& s) { b_.insert(b_.end(), s.begin(), s.end()); }
  const std::vector<uint8_t>& bytes() const { return b_; }
  size_t size() const { return b_.size(); }

 private:
  std::vector<uint8_t> b_;
};

template <typename T>
T Get(const std::vector<uint8_t>& b, size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof(T));
  return v;
}

}  // namespace

void WriteLas(const fs::path& path, const std::vector<Eigen::Vector3d>& pts, const std::vector<io::Rgb8>& colors,
              const std::string& wkt) {
  if (!colors.empty() && colors.size() != pts.size()) throw Error(path.string() + ": colour count differs from points");
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(0), hi = Eigen::Vector3d::Constant(0);
  if (!pts.empty()) {
    lo = hi = pts.front();
    for (const auto& p : pts) {
      if (!p.allFinite()) throw Error(path.string() + ": a point is not finite");
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  const double scale = 0.001;
  const Eigen::Vector3d offset = (lo / 1000).array().floor() * 1000;  // round km: readable, and in range
  if (((hi - offset) / scale).maxCoeff() > 2147483647.0)
    throw Error(path.string() + ": the cloud spans more than 2,000 km, too wide for 1 mm LAS integers");
  const std::string wkt_z = wkt + std::string(1, '\0');

  Buf h;
  h.PutString("LASF", 4);
  h.Put<uint16_t>(0);        // file source id
  h.Put<uint16_t>(1u << 4);  // global encoding: CRS is WKT
  h.PutString("", 16);       // project GUID
  h.Put<uint8_t>(1);
  h.Put<uint8_t>(4);
  h.PutString("fmv3d", 32);
  h.PutString("fmv3d " FMV3D_VERSION, 32);
  const std::time_t now = CreationTime();
  std::tm tm{};
  gmtime_r(&now, &tm);
  h.Put<uint16_t>(static_cast<uint16_t>(tm.tm_yday + 1));
  h.Put<uint16_t>(static_cast<uint16_t>(tm.tm_year + 1900));
  h.Put<uint16_t>(kHeaderSize);
  h.Put<uint32_t>(static_cast<uint32_t>(kHeaderSize + kVlrHeaderSize + wkt_z.size()));  // offset to points
  h.Put<uint32_t>(1);                                                                   // one VLR
  h.Put<uint8_t>(kFormat);
  h.Put<uint16_t>(kRecordLength);
  h.Put<uint32_t>(0);  // legacy point count: 0 for formats 6-10
  for (int i = 0; i < 5; ++i) h.Put<uint32_t>(0);
  for (int i = 0; i < 3; ++i) h.Put<double>(scale);
  for (int i = 0; i < 3; ++i) h.Put<double>(offset[i]);
  for (int i = 0; i < 3; ++i) {
    h.Put<double>(hi[i]);
    h.Put<double>(lo[i]);
  }
  h.Put<uint64_t>(0);  // waveform data
  h.Put<uint64_t>(0);  // first EVLR
  h.Put<uint32_t>(0);  // EVLR count
  h.Put<uint64_t>(pts.size());
  h.Put<uint64_t>(pts.size());  // all single returns
  for (int i = 1; i < 15; ++i) h.Put<uint64_t>(0);
  if (h.size() != kHeaderSize) throw Error("LAS: internal header size error");
  // VLR: the OGC coordinate system WKT.
  if (wkt_z.size() > 65535) throw Error("LAS: CRS WKT too long");
  h.Put<uint16_t>(0);
  h.PutString("LASF_Projection", 16);
  h.Put<uint16_t>(2112);
  h.Put<uint16_t>(static_cast<uint16_t>(wkt_z.size()));
  h.PutString("OGC coordinate system WKT", 32);
  h.PutBytes(wkt_z);

  core::WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    if (!f) throw Error(path.string() + ": cannot create");
    f.write(reinterpret_cast<const char*>(h.bytes().data()), static_cast<std::streamsize>(h.size()));
    Buf rec;
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d q = ((pts[i] - offset) / scale).array().round();
      rec.Put<int32_t>(static_cast<int32_t>(q.x()));
      rec.Put<int32_t>(static_cast<int32_t>(q.y()));
      rec.Put<int32_t>(static_cast<int32_t>(q.z()));
      rec.Put<uint16_t>(0);    // intensity
      rec.Put<uint8_t>(0x11);  // return 1 of 1
      rec.Put<uint8_t>(0);     // flags, channel, scan direction, edge
      rec.Put<uint8_t>(1);     // classification: unclassified
      rec.Put<uint8_t>(0);     // user data
      rec.Put<int16_t>(0);     // scan angle
      rec.Put<uint16_t>(0);    // point source
      rec.Put<double>(0);      // GPS time
      const io::Rgb8 c = colors.empty() ? io::Rgb8(255, 255, 255) : colors[i];
      for (int k = 0; k < 3; ++k) rec.Put<uint16_t>(static_cast<uint16_t>(c[k] * 257));  // 16-bit colour
      if (rec.size() >= (1 << 20) || i + 1 == pts.size()) {
        f.write(reinterpret_cast<const char*>(rec.bytes().data()), static_cast<std::streamsize>(rec.size()));
        rec = Buf();
      }
    }
    if (!f) throw Error(path.string() + ": write failed");
  });
}

LasInfo ReadLas(const fs::path& path, bool read_points) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error(path.string() + ": cannot open");
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (b.size() < kHeaderSize || std::memcmp(b.data(), "LASF", 4) != 0) throw Error(path.string() + ": not a LAS file");
  LasInfo info;
  info.version_major = b[24];
  info.version_minor = b[25];
  if (info.version_major != 1 || info.version_minor != 4) throw Error(path.string() + ": not LAS 1.4");
  const uint16_t header_size = Get<uint16_t>(b, 94);
  const uint32_t offset_points = Get<uint32_t>(b, 96);
  const uint32_t nvlr = Get<uint32_t>(b, 100);
  info.creation_day = Get<uint16_t>(b, 90);
  info.creation_year = Get<uint16_t>(b, 92);
  info.point_format = b[104] & 0x3F;
  info.point_record_length = Get<uint16_t>(b, 105);
  for (int i = 0; i < 3; ++i) {
    info.scale[i] = Get<double>(b, 131 + 8 * i);
    info.offset[i] = Get<double>(b, 155 + 8 * i);
    info.max[i] = Get<double>(b, 179 + 16 * i);
    info.min[i] = Get<double>(b, 187 + 16 * i);
  }
  info.num_points = Get<uint64_t>(b, 247);
  size_t at = header_size;
  for (uint32_t v = 0; v < nvlr; ++v) {
    if (at + kVlrHeaderSize > b.size()) throw Error(path.string() + ": truncated VLR");
    const std::string user(reinterpret_cast<const char*>(&b[at + 2]),
                           strnlen(reinterpret_cast<const char*>(&b[at + 2]), 16));
    const uint16_t id = Get<uint16_t>(b, at + 18), len = Get<uint16_t>(b, at + 20);
    if (at + kVlrHeaderSize + len > b.size()) throw Error(path.string() + ": truncated VLR");
    if (user == "LASF_Projection" && id == 2112)
      info.wkt.assign(reinterpret_cast<const char*>(&b[at + kVlrHeaderSize]),
                      strnlen(reinterpret_cast<const char*>(&b[at + kVlrHeaderSize]), len));
    at += kVlrHeaderSize + len;
  }
  if (info.num_points > b.size() || offset_points > b.size() ||
      offset_points + info.num_points * info.point_record_length > b.size())
    throw Error(path.string() + ": truncated point data");
  if (read_points) {
    if (info.point_format < 6 || info.point_record_length < 30)
      throw Error(path.string() + ": unsupported point format");
    for (uint64_t i = 0; i < info.num_points; ++i) {
      const size_t p = offset_points + i * info.point_record_length;
      Eigen::Vector3d x;
      for (int k = 0; k < 3; ++k)
        x[k] = Get<int32_t>(b, p + size_t{4} * static_cast<size_t>(k)) * info.scale[k] + info.offset[k];
      info.points.push_back(x);
    }
  }
  return info;
}

}  // namespace fmv3d::geo
