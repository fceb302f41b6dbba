#include "fmv3d/io/mesh.h"

#include "fmv3d/core/error.h"

namespace fmv3d::io {

void TexturedMesh::Append(const TexturedMesh& other) {
  const int v0 = static_cast<int>(vertices.size()), t0 = static_cast<int>(uvs.size());
  const int n0 = static_cast<int>(normals.size()), m0 = static_cast<int>(materials.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  uvs.insert(uvs.end(), other.uvs.begin(), other.uvs.end());
  normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  materials.insert(materials.end(), other.materials.begin(), other.materials.end());
  faces.reserve(faces.size() + other.faces.size());
  for (Face f : other.faces) {
    for (int k = 0; k < 3; ++k) {
      f.v[k] += v0;
      if (f.vt[k] >= 0) f.vt[k] += t0;
      if (f.vn[k] >= 0) f.vn[k] += n0;
    }
    if (f.material >= 0) f.material += m0;
    faces.push_back(f);
  }
}

Eigen::AlignedBox3d TexturedMesh::Bounds() const {
  Eigen::AlignedBox3d box;
  for (const auto& v : vertices) box.extend(v);
  return box;
}

Eigen::Vector3d TexturedMesh::FaceNormal(size_t i) const {
  const Face& f = faces[i];
  const Eigen::Vector3d n = (vertices[f.v[1]] - vertices[f.v[0]]).cross(vertices[f.v[2]] - vertices[f.v[0]]);
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

double TexturedMesh::SurfaceArea() const {
  double a = 0;
  for (const Face& f : faces)
    a += 0.5 * (vertices[f.v[1]] - vertices[f.v[0]]).cross(vertices[f.v[2]] - vertices[f.v[0]]).norm();
  return a;
}

void TexturedMesh::Validate() const {
  const int nv = static_cast<int>(vertices.size()), nt = static_cast<int>(uvs.size());
  const int nn = static_cast<int>(normals.size()), nm = static_cast<int>(materials.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    const Face& f = faces[i];
    for (int k = 0; k < 3; ++k) {
      if (f.v[k] < 0 || f.v[k] >= nv || f.vt[k] >= nt || f.vn[k] >= nn)
        throw Error("mesh: face " + std::to_string(i) + " refers to a missing vertex, uv or normal");
    }
    if (f.material >= nm) throw Error("mesh: face " + std::to_string(i) + " refers to a missing material");
  }
}

}  // namespace fmv3d::io
