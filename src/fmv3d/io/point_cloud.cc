#include "fmv3d/io/point_cloud.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/ply_scalar.h"

namespace fmv3d::io {

namespace fs = std::filesystem;

void OrientedPointCloud::Reserve(size_t n) {
  positions.reserve(n);
  normals.reserve(n);
  colors.reserve(n);
  visibility.reserve(n);
  if (has_sigma()) sigma.reserve(n);
}

void OrientedPointCloud::Append(const OrientedPointCloud& other) {
  if (empty()) {
    *this = other;
    return;
  }
  const bool keep_n = has_normals() && other.has_normals();
  const bool keep_c = has_colors() && other.has_colors();
  const bool keep_v = has_visibility() && other.has_visibility();
  const bool keep_s = has_sigma() && other.has_sigma();
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  if (keep_n)
    normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  else
    normals.clear();
  if (keep_c)
    colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  else
    colors.clear();
  if (keep_v)
    visibility.insert(visibility.end(), other.visibility.begin(), other.visibility.end());
  else
    visibility.clear();
  if (keep_s)
    sigma.insert(sigma.end(), other.sigma.begin(), other.sigma.end());
  else
    sigma.clear();
}

Eigen::AlignedBox3d OrientedPointCloud::Bounds() const {
  Eigen::AlignedBox3d box;
  box.setEmpty();
  for (const auto& p : positions) box.extend(p);
  return box;
}

void OrientedPointCloud::Validate() const {
  const size_t n = positions.size();
  if ((!normals.empty() && normals.size() != n) || (!colors.empty() && colors.size() != n) ||
      (!visibility.empty() && visibility.size() != n) || (!sigma.empty() && sigma.size() != n))
    throw Error("point cloud: attribute count differs from the point count");
}

void WritePointCloudPly(const OrientedPointCloud& cloud, const fs::path& path) {
  cloud.Validate();
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(tmp.string() + ": cannot write");
    out << "ply\nformat binary_little_endian 1.0\ncomment fmv3d oriented points\nelement vertex " << cloud.size()
        << "\nproperty float x\nproperty float y\nproperty float z\n";
    if (cloud.has_normals()) out << "property float nx\nproperty float ny\nproperty float nz\n";
    if (cloud.has_colors()) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    if (cloud.has_sigma()) out << "property float sigma\n";
    if (cloud.has_visibility()) out << "property list uchar int visibility\n";
    out << "end_header\n";
    std::string buf;
    for (size_t i = 0; i < cloud.size(); ++i) {
      buf.clear();
      auto put = [&](const void* p, size_t n) { buf.append(static_cast<const char*>(p), n); };
      const float xyz[3] = {float(cloud.positions[i].x()), float(cloud.positions[i].y()),
                            float(cloud.positions[i].z())};
      put(xyz, sizeof xyz);
      if (cloud.has_normals()) put(cloud.normals[i].data(), 3 * sizeof(float));
      if (cloud.has_colors()) put(cloud.colors[i].data(), 3);
      if (cloud.has_sigma()) put(&cloud.sigma[i], sizeof(float));
      if (cloud.has_visibility()) {
        const auto& v = cloud.visibility[i];
        const uint8_t n = static_cast<uint8_t>(std::min<size_t>(v.size(), 255));
        put(&n, 1);
        for (int k = 0; k < n; ++k) {
          const int32_t id = static_cast<int32_t>(v[k]);
          put(&id, 4);
        }
      }
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    }
    if (!out) throw Error(tmp.string() + ": write failed");
  });
}

namespace {

using Type = ply::Scalar;

Type ParseType(const std::string& s, const std::string& file) {
  if (const auto t = ply::ScalarFromName(s)) return *t;
  throw Error(file + ": unknown PLY property type '" + s + "'");
}

using ply::SizeOf;

struct Property {
  std::string name;
  bool is_list = false;
  Type count_type = Type::kU8, type = Type::kF32;
};

struct Element {
  std::string name;
  size_t count = 0;
  std::vector<Property> props;
};

// Reads values of one element, in ascii or binary (with or without byte swap).
class ValueReader {
 public:
  ValueReader(std::istream& in, int format, const std::string& file) : in_(in), format_(format), file_(file) {}
  double Read(Type t) {
    if (format_ == 0) {
      double v;
      if (!(in_ >> v)) throw Error(file_ + ": truncated or malformed ascii PLY data");
      return v;
    }
    unsigned char b[8];
    const size_t n = SizeOf(t);
    if (!in_.read(reinterpret_cast<char*>(b), static_cast<std::streamsize>(n)))
      throw Error(file_ + ": truncated PLY data");
    if (format_ == 2) std::reverse(b, b + n);
    return ply::Decode(t, reinterpret_cast<const char*>(b));
  }

 private:
  std::istream& in_;
  int format_;  // 0 ascii, 1 binary little endian, 2 binary big endian
  const std::string& file_;
};

}  // namespace

OrientedPointCloud ReadPointCloudPly(const fs::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(file + ": cannot open");
  std::string line;
  if (!std::getline(in, line) || line.rfind("ply", 0) != 0) throw Error(file + ": not a PLY file");
  int format = -1;
  std::vector<Element> elements;
  while (true) {
    if (!std::getline(in, line)) throw Error(file + ": PLY header has no end_header");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "end_header") break;
    if (word == "format") {
      std::string f;
      ls >> f;
      format = f == "ascii" ? 0 : f == "binary_little_endian" ? 1 : f == "binary_big_endian" ? 2 : -1;
      if (format < 0) throw Error(file + ": unknown PLY format '" + f + "'");
    } else if (word == "element") {
      Element e;
      long long count = -1;
      ls >> e.name >> count;
      if (count < 0 || count > (1LL << 34)) throw Error(file + ": bad PLY element count");
      e.count = static_cast<size_t>(count);
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) throw Error(file + ": PLY property before any element");
      Property p;
      std::string t;
      ls >> t;
      if (t == "list") {
        std::string ct, it;
        ls >> ct >> it >> p.name;
        p.is_list = true;
        p.count_type = ParseType(ct, file);
        p.type = ParseType(it, file);
      } else {
        p.type = ParseType(t, file);
        ls >> p.name;
      }
      elements.back().props.push_back(p);
    }
  }
  if (format < 0) throw Error(file + ": PLY header has no format line");
  // Counts must fit the bytes that follow the header (an ascii value takes at least 2 bytes, a binary one its
  // size), so a corrupt count is an error rather than a huge allocation.
  const std::streamoff data_start = in.tellg();
  in.seekg(0, std::ios::end);
  const auto data_bytes = static_cast<unsigned long long>(std::max<std::streamoff>(0, in.tellg() - data_start));
  in.seekg(data_start);
  unsigned long long needed = 0;
  for (const Element& e : elements) {
    unsigned long long record = 0;
    for (const Property& p : e.props) record += format == 0 ? 2 : SizeOf(p.is_list ? p.count_type : p.type);
    needed += e.count * std::max<unsigned long long>(record, 1);
    if (needed > data_bytes)
      throw Error(file + ": truncated PLY: element '" + e.name + "' needs at least " + std::to_string(needed) +
                  " bytes of data, the file has " + std::to_string(data_bytes));
  }

  OrientedPointCloud cloud;
  ValueReader reader(in, format, file);
  for (const Element& e : elements) {
    const bool is_vertex = e.name == "vertex";
    int ix = -1, iy = -1, iz = -1, inx = -1, iny = -1, inz = -1, ir = -1, ig = -1, ib = -1, ivis = -1, isig = -1;
    for (size_t k = 0; k < e.props.size(); ++k) {
      const auto& n = e.props[k].name;
      const int kk = static_cast<int>(k);
      if (n == "x")
        ix = kk;
      else if (n == "y")
        iy = kk;
      else if (n == "z")
        iz = kk;
      else if (n == "nx")
        inx = kk;
      else if (n == "ny")
        iny = kk;
      else if (n == "nz")
        inz = kk;
      else if (n == "red" || n == "r")
        ir = kk;
      else if (n == "green" || n == "g")
        ig = kk;
      else if (n == "blue" || n == "b")
        ib = kk;
      else if (n == "visibility" && e.props[k].is_list)
        ivis = kk;
      else if (n == "sigma" && !e.props[k].is_list)
        isig = kk;
    }
    if (is_vertex) {
      if (ix < 0 || iy < 0 || iz < 0) throw Error(file + ": PLY vertices have no x, y, z");
      cloud.positions.resize(e.count);
      if (inx >= 0 && iny >= 0 && inz >= 0) cloud.normals.resize(e.count);
      if (ir >= 0 && ig >= 0 && ib >= 0) cloud.colors.resize(e.count);
      if (ivis >= 0) cloud.visibility.resize(e.count);
      if (isig >= 0) cloud.sigma.resize(e.count);
    }
    std::vector<double> values(e.props.size());
    for (size_t i = 0; i < e.count; ++i) {
      for (size_t k = 0; k < e.props.size(); ++k) {
        const Property& p = e.props[k];
        if (!p.is_list) {
          values[k] = reader.Read(p.type);
          continue;
        }
        const double n = reader.Read(p.count_type);
        if (n < 0 || n > 1e6) throw Error(file + ": bad PLY list length");
        const bool keep = is_vertex && static_cast<int>(k) == ivis;
        for (int j = 0; j < static_cast<int>(n); ++j) {
          const double v = reader.Read(p.type);
          if (!keep) continue;
          if (!(v >= 0 && v <= 4294967295.0)) throw Error(file + ": bad PLY visibility index");
          cloud.visibility[i].push_back(static_cast<uint32_t>(v));
        }
      }
      if (!is_vertex) continue;
      cloud.positions[i] = {values[ix], values[iy], values[iz]};
      if (cloud.has_sigma()) cloud.sigma[i] = static_cast<float>(values[isig]);
      if (cloud.has_normals()) cloud.normals[i] = {float(values[inx]), float(values[iny]), float(values[inz])};
      if (cloud.has_colors()) {
        // Float colours in [0, 1] are scaled to 8 bits.
        const bool unit = e.props[ir].type == Type::kF32 || e.props[ir].type == Type::kF64;
        auto c8 = [&](double v) {
          if (std::isnan(v)) return uint8_t{0};
          return static_cast<uint8_t>(std::clamp(unit ? v * 255.0 + 0.5 : v, 0.0, 255.0));
        };
        cloud.colors[i] = {c8(values[ir]), c8(values[ig]), c8(values[ib])};
      }
    }
    if (is_vertex) break;  // later elements (faces) are not needed
  }
  return cloud;
}

}  // namespace fmv3d::io
