#include "fmv3d/io/point_cloud.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/ply_header.h"
#include "fmv3d/io/ply_mesh.h"

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
using ply::SizeOf;

// Reads values of one element, in ascii or binary (with or without byte swap).
class ValueReader {
 public:
  ValueReader(std::istream& in, ply::Format format, const std::string& file) : in_(in), format_(format), file_(file) {}
  double Read(Type t) {
    if (format_ == ply::Format::kAscii) {
      double v;
      if (!(in_ >> v)) throw Error(file_ + ": truncated or malformed ascii PLY data");
      return v;
    }
    unsigned char b[8];
    const size_t n = SizeOf(t);
    if (!in_.read(reinterpret_cast<char*>(b), static_cast<std::streamsize>(n)))
      throw Error(file_ + ": truncated PLY data");
    if (format_ == ply::Format::kBinaryBigEndian) std::reverse(b, b + n);
    return ply::Decode(t, reinterpret_cast<const char*>(b));
  }

 private:
  std::istream& in_;
  ply::Format format_;
  const std::string& file_;
};

// Where the vertex element keeps the properties the cloud holds (-1: absent).
struct VertexColumns {
  int x = -1, y = -1, z = -1, nx = -1, ny = -1, nz = -1, r = -1, g = -1, b = -1, visibility = -1, sigma = -1;
  explicit VertexColumns(const ply::Element& e) {
    auto either = [&](const char* a, const char* b) { return std::max(e.Find(a), e.Find(b)); };
    x = e.Find("x"), y = e.Find("y"), z = e.Find("z");
    nx = e.Find("nx"), ny = e.Find("ny"), nz = e.Find("nz");
    r = either("red", "r"), g = either("green", "g"), b = either("blue", "b");
    visibility = e.Find("visibility", true);
    sigma = e.Find("sigma");
  }
};

// Where the face element keeps its vertex list (-1: absent).
int FaceIndexColumn(const ply::Element& e) {
  return std::max(e.Find("vertex_indices", true), e.Find("vertex_index", true));
}

// Reads one element's records; a vertex element fills the cloud, a face element (when `triangles` is given) its
// fan-triangulated polygons, any other is read past.
void ReadElement(const ply::Element& e, ValueReader& reader, const std::string& file, OrientedPointCloud& cloud,
                 std::vector<Eigen::Vector3i>* triangles = nullptr) {
  const bool is_vertex = e.name == "vertex";
  const int face_list = (triangles != nullptr && e.name == "face") ? FaceIndexColumn(e) : -1;
  const VertexColumns c(e);
  if (is_vertex) {
    if (c.x < 0 || c.y < 0 || c.z < 0) throw Error(file + ": PLY vertices have no x, y, z");
    cloud.positions.resize(e.count);
    if (c.nx >= 0 && c.ny >= 0 && c.nz >= 0) cloud.normals.resize(e.count);
    if (c.r >= 0 && c.g >= 0 && c.b >= 0) cloud.colors.resize(e.count);
    if (c.visibility >= 0) cloud.visibility.resize(e.count);
    if (c.sigma >= 0) cloud.sigma.resize(e.count);
  }
  // Float colours in [0, 1] are scaled to 8 bits.
  const bool unit_colour =
      is_vertex && cloud.has_colors() && (e.properties[c.r].type == Type::kF32 || e.properties[c.r].type == Type::kF64);
  auto c8 = [&](double v) {
    if (std::isnan(v)) return uint8_t{0};
    return static_cast<uint8_t>(std::clamp(unit_colour ? v * 255.0 + 0.5 : v, 0.0, 255.0));
  };
  const double vertex_count = static_cast<double>(cloud.size());
  std::vector<double> values(e.properties.size());
  std::vector<int> polygon;
  for (size_t i = 0; i < e.count; ++i) {
    for (size_t k = 0; k < e.properties.size(); ++k) {
      const ply::Property& p = e.properties[k];
      if (!p.is_list) {
        values[k] = reader.Read(p.type);
        continue;
      }
      const double n = reader.Read(p.count_type);
      if (n < 0 || n > 1e6) throw Error(file + ": bad PLY list length");
      const bool keep = is_vertex && static_cast<int>(k) == c.visibility;
      const bool face = static_cast<int>(k) == face_list;
      if (face && n < 3) throw Error(file + ": PLY face " + std::to_string(i) + " has fewer than 3 vertices");
      polygon.clear();
      for (int j = 0; j < static_cast<int>(n); ++j) {
        const double v = reader.Read(p.type);
        if (face) {
          if (!(v >= 0 && v < vertex_count))
            throw Error(file + ": PLY face " + std::to_string(i) + " names a vertex that does not exist");
          polygon.push_back(static_cast<int>(v));
        }
        if (!keep) continue;
        if (!(v >= 0 && v <= 4294967295.0)) throw Error(file + ": bad PLY visibility index");
        cloud.visibility[i].push_back(static_cast<uint32_t>(v));
      }
      for (size_t j = 2; face && j < polygon.size(); ++j)
        triangles->emplace_back(polygon[0], polygon[j - 1], polygon[j]);
    }
    if (!is_vertex) continue;
    cloud.positions[i] = {values[c.x], values[c.y], values[c.z]};
    if (cloud.has_sigma()) cloud.sigma[i] = static_cast<float>(values[c.sigma]);
    if (cloud.has_normals()) cloud.normals[i] = {float(values[c.nx]), float(values[c.ny]), float(values[c.nz])};
    if (cloud.has_colors()) cloud.colors[i] = {c8(values[c.r]), c8(values[c.g]), c8(values[c.b])};
  }
}

// Opens `path` and reads its header, checking the counts fit the bytes after it; leaves `in` at the data.
ply::Header OpenPly(std::ifstream& in, const fs::path& path) {
  const std::string file = path.string();
  if (!in) throw Error(file + ": cannot open");
  ply::Header header = ply::ReadHeader(in, file);
  const std::streamoff data_start = in.tellg();
  in.seekg(0, std::ios::end);
  const auto data_bytes = static_cast<unsigned long long>(std::max<std::streamoff>(0, in.tellg() - data_start));
  in.seekg(data_start);
  ply::CheckCountsFit(header, data_bytes, file);
  return header;
}

}  // namespace

OrientedPointCloud ReadPointCloudPly(const fs::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  const ply::Header header = OpenPly(in, path);
  OrientedPointCloud cloud;
  ValueReader reader(in, header.format, file);
  for (const ply::Element& e : header.elements) {
    ReadElement(e, reader, file, cloud);
    if (e.name == "vertex") break;  // later elements (faces) are not needed
  }
  return cloud;
}

PlyMesh ReadMeshPly(const fs::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  const ply::Header header = OpenPly(in, path);
  bool seen_vertices = false;
  for (const ply::Element& e : header.elements) {
    if (e.name == "vertex") seen_vertices = true;
    if (e.name == "face" && !seen_vertices) throw Error(file + ": PLY faces come before the vertices they index");
    if (e.name == "face" && FaceIndexColumn(e) < 0) throw Error(file + ": PLY faces have no vertex_indices list");
  }
  if (!seen_vertices) throw Error(file + ": PLY has no vertex element");
  PlyMesh mesh;
  ValueReader reader(in, header.format, file);
  for (const ply::Element& e : header.elements) {
    ReadElement(e, reader, file, mesh.vertices, &mesh.triangles);
    if (e.name == "face") break;  // later elements are not needed
  }
  return mesh;
}

}  // namespace fmv3d::io
