#include "fmv3d/surface/colored_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/ply_mesh.h"

namespace fmv3d::surface {

namespace fs = std::filesystem;

Eigen::AlignedBox3d ColoredMesh::Bounds() const {
  Eigen::AlignedBox3d box;
  for (const auto& v : vertices) box.extend(v);
  return box;
}

double ColoredMesh::SurfaceArea() const {
  double area = 0;
  for (const auto& t : triangles)
    area += 0.5 * (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]).norm();
  return area;
}

void ColoredMesh::ComputeVertexNormals() {
  std::vector<Eigen::Vector3d> acc(vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& t : triangles) {
    // The unnormalised cross product weighs each face by its area.
    const Eigen::Vector3d n = (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]);
    for (int k = 0; k < 3; ++k) acc[t[k]] += n;
  }
  normals.resize(vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    const double len = acc[i].norm();
    normals[i] = len > 0 ? Eigen::Vector3f((acc[i] / len).cast<float>()) : Eigen::Vector3f::UnitZ();
  }
}

void ColoredMesh::Validate() const {
  if (!normals.empty() && normals.size() != vertices.size())
    throw Error("mesh: normal count differs from the vertex count");
  if (!colors.empty() && colors.size() != vertices.size())
    throw Error("mesh: colour count differs from the vertex count");
  const int n = static_cast<int>(vertices.size());
  for (const auto& t : triangles)
    for (int k = 0; k < 3; ++k)
      if (t[k] < 0 || t[k] >= n) throw Error("mesh: triangle refers to a missing vertex");
}

io::TexturedMesh ColoredMesh::ToTexturedMesh() const {
  io::TexturedMesh m;
  m.vertices = vertices;
  m.faces.resize(triangles.size());
  for (size_t i = 0; i < triangles.size(); ++i)
    for (int k = 0; k < 3; ++k) m.faces[i].v[k] = triangles[i][k];
  return m;
}

void WriteMeshPly(const ColoredMesh& mesh, const fs::path& path) {
  mesh.Validate();
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(tmp.string() + ": cannot write");
    const bool has_n = !mesh.normals.empty(), has_c = !mesh.colors.empty();
    out << "ply\nformat binary_little_endian 1.0\ncomment fmv3d surface mesh\nelement vertex " << mesh.vertices.size()
        << "\nproperty float x\nproperty float y\nproperty float z\n";
    if (has_n) out << "property float nx\nproperty float ny\nproperty float nz\n";
    if (has_c) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    out << "element face " << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    // One buffer per element keeps the write fast for million-face meshes.
    const size_t vsize = 12 + (has_n ? 12 : 0) + (has_c ? 3 : 0);
    std::vector<char> buf(vsize * mesh.vertices.size());
    char* p = buf.data();
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const float xyz[3] = {static_cast<float>(mesh.vertices[i].x()), static_cast<float>(mesh.vertices[i].y()),
                            static_cast<float>(mesh.vertices[i].z())};
      std::memcpy(p, xyz, 12);
      p += 12;
      if (has_n) {
        std::memcpy(p, mesh.normals[i].data(), 12);
        p += 12;
      }
      if (has_c) {
        std::memcpy(p, mesh.colors[i].data(), 3);
        p += 3;
      }
    }
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    buf.assign(13 * mesh.triangles.size(), 0);
    p = buf.data();
    for (const auto& t : mesh.triangles) {
      *p++ = 3;
      const int32_t idx[3] = {t[0], t[1], t[2]};
      std::memcpy(p, idx, 12);
      p += 12;
    }
    out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
    if (!out) throw Error(tmp.string() + ": write failed");
  });
}

ColoredMesh ReadMeshPly(const fs::path& path) {
  if (!fs::exists(path)) throw Error(path.string() + ": no such file");
  io::PlyMesh ply = io::ReadMeshPly(path);
  if (ply.triangles.empty()) throw Error(path.string() + ": the mesh has no triangles");
  ColoredMesh mesh;
  mesh.vertices = std::move(ply.vertices.positions);
  mesh.normals = std::move(ply.vertices.normals);
  mesh.colors = std::move(ply.vertices.colors);
  mesh.triangles = std::move(ply.triangles);
  mesh.Validate();
  return mesh;
}

}  // namespace fmv3d::surface
