#include "fmv3d/io/ply_stream.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/io/ply_header.h"

namespace fmv3d::io {

namespace {

using ply::Scalar;

struct Property {
  Scalar type = Scalar::kF32;        // scalar type, or the list's item type
  std::optional<Scalar> count_type;  // set for lists
  int slot = -1;  // 0-2 position, 3-5 normal, 6-8 colour, 9 the visibility list, 10 sigma, -1 ignored
};

// Buffered little reader: Take(n) returns a pointer to the next n bytes.
class Buffer {
 public:
  Buffer(std::ifstream& in, const std::filesystem::path& path) : in_(in), path_(path), data_(1 << 20) {}
  const char* Take(size_t n) {
    if (end_ - pos_ < n) Refill(n);
    const char* p = data_.data() + pos_;
    pos_ += n;
    return p;
  }

 private:
  void Refill(size_t n) {
    std::memmove(data_.data(), data_.data() + pos_, end_ - pos_);
    end_ -= pos_;
    pos_ = 0;
    if (data_.size() < n) data_.resize(n);
    in_.read(data_.data() + end_, static_cast<std::streamsize>(data_.size() - end_));
    end_ += static_cast<size_t>(in_.gcount());
    if (end_ < n) throw Error(path_.string() + ": the PLY ends before its last vertex");
  }
  std::ifstream& in_;
  const std::filesystem::path& path_;
  std::vector<char> data_;
  size_t pos_ = 0, end_ = 0;
};

// Where each property of the vertex element goes: 0-2 position, 3-5 normal, 6-8 colour, 9 the visibility list,
// 10 sigma, -1 ignored.
int SlotOf(const ply::Property& p) {
  static const char* kSlots[] = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"};
  if (p.is_list) return p.name == "visibility" ? 9 : -1;
  for (int s = 0; s < 9; ++s)
    if (p.name == kSlots[s]) return s;
  return p.name == "sigma" ? 10 : -1;
}

}  // namespace

bool StreamPlyVertices(const std::filesystem::path& path, const std::function<void(size_t)>& on_count,
                       const std::function<void(const PlyVertex&)>& on_vertex) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open for reading");
  const ply::Header header = ply::ReadHeader(in, path.string());
  if (header.format != ply::Format::kBinaryLittleEndian) return false;
  if (header.elements.empty() || header.elements[0].name != "vertex") return false;
  const size_t count = header.elements[0].count;
  std::vector<Property> props;
  for (const ply::Property& hp : header.elements[0].properties) {
    Property p;
    p.type = hp.type;
    if (hp.is_list) p.count_type = hp.count_type;
    p.slot = SlotOf(hp);
    props.push_back(p);
  }
  if (on_count) on_count(count);
  Buffer buf(in, path);
  PlyVertex v;
  for (size_t i = 0; i < count; ++i) {
    for (const Property& p : props) {
      if (p.count_type) {
        const double n = ply::Decode(*p.count_type, buf.Take(ply::SizeOf(*p.count_type)));
        if (n < 0 || n > 1e6) throw Error(path.string() + ": implausible PLY list length");
        buf.Take(static_cast<size_t>(n) * ply::SizeOf(p.type));
        if (p.slot == 9) v.views = static_cast<uint8_t>(std::min(n, 255.0));
        continue;
      }
      const double x = ply::Decode(p.type, buf.Take(ply::SizeOf(p.type)));
      if (p.slot < 0) continue;
      if (p.slot < 3)
        v.position[p.slot] = static_cast<float>(x);
      else if (p.slot < 6)
        v.normal[p.slot - 3] = static_cast<float>(x);
      else if (p.slot == 10)
        v.sigma = static_cast<float>(x);
      else
        v.rgb[p.slot - 6] = static_cast<uint8_t>(x);
    }
    on_vertex(v);
  }
  return true;
}

}  // namespace fmv3d::io
