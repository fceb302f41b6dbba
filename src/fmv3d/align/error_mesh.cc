#include "fmv3d/align/error_mesh.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>

#include "fmv3d/align/point_index.h"
#include "fmv3d/core/error.h"

namespace fmv3d::align {

void ErrorMeshOptions::Check() const {
  if (!(max_edge > 0)) throw Error("error mesh: max_edge must be > 0");
  if (max_triangles < 1) throw Error("error mesh: max_triangles must be >= 1");
  if (!(radius > 0)) throw Error("error mesh: radius must be > 0");
  if (!(scale > 0)) throw Error("error mesh: scale must be > 0");
  if (!(length > 0)) throw Error("error mesh: length must be > 0");
}

io::Rgb8 DivergingColor(double t) {
  if (!std::isfinite(t)) return {128, 128, 128};
  t = std::clamp(t, -1.0, 1.0);
  // Blue (59, 76, 192) → white → red (180, 4, 38): the two halves of the cool-warm map, linear in RGB.
  const Eigen::Vector3d white(245, 245, 245), cold(59, 76, 192), warm(180, 4, 38);
  const Eigen::Vector3d c = t < 0 ? white + (-t) * (cold - white) : white + t * (warm - white);
  return c.array().round().cast<uint8_t>();
}

ErrorMesh BuildErrorMesh(const io::TexturedMesh& cad, const std::vector<Eigen::Vector3d>& points,
                         const std::vector<double>& signed_error, const ErrorMeshOptions& o) {
  o.Check();
  if (points.size() != signed_error.size()) throw Error("error mesh: one error per point is needed");
  cad.Validate();
  // Subdivisions per face: its longest edge over max_edge, all scaled down together when over the triangle cap.
  std::vector<double> wanted(cad.faces.size());
  double total = 0;
  for (size_t f = 0; f < cad.faces.size(); ++f) {
    const auto& v = cad.faces[f].v;
    double longest = 0;
    for (int k = 0; k < 3; ++k) longest = std::max(longest, (cad.vertices[v[k]] - cad.vertices[v[(k + 1) % 3]]).norm());
    wanted[f] = std::max(1.0, std::ceil(longest / o.max_edge));
    total += wanted[f] * wanted[f];
  }
  const double shrink = total > static_cast<double>(o.max_triangles) ? std::sqrt(o.max_triangles / total) : 1.0;
  ErrorMesh m;
  for (size_t f = 0; f < cad.faces.size(); ++f) {
    const int n = std::max(1, static_cast<int>(std::floor(wanted[f] * shrink)));
    const Eigen::Vector3d a = cad.vertices[cad.faces[f].v[0]], b = cad.vertices[cad.faces[f].v[1]],
                          c = cad.vertices[cad.faces[f].v[2]];
    // Vertices on the barycentric grid: row i (0..n) from edge a towards c, column j (0..n−i) along a→b.
    const int base = static_cast<int>(m.vertices.size());
    std::vector<int> row_start(n + 2);
    for (int i = 0, id = 0; i <= n; ++i) {
      row_start[i] = id;
      for (int j = 0; j <= n - i; ++j, ++id)
        m.vertices.push_back(a + (b - a) * (double(j) / n) + (c - a) * (double(i) / n));
    }
    auto at = [&](int i, int j) { return base + row_start[i] + j; };
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n - i; ++j) {
        m.triangles.emplace_back(at(i, j), at(i, j + 1), at(i + 1, j));
        if (j + 1 < n - i) m.triangles.emplace_back(at(i, j + 1), at(i + 1, j + 1), at(i + 1, j));
      }
  }
  m.error.assign(m.vertices.size(), std::numeric_limits<float>::quiet_NaN());
  m.colors.assign(m.vertices.size(), DivergingColor(std::numeric_limits<double>::quiet_NaN()));
  if (points.empty()) return m;
  const PointIndex index(points);
  const double r2 = o.radius * o.radius;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, m.vertices.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    std::vector<int> nn;
    std::vector<double> d2;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      index.Knn(m.vertices[i], 16, &nn, &d2);
      double sum = 0;
      int count = 0;
      for (size_t k = 0; k < nn.size(); ++k)
        if (d2[k] <= r2) sum += signed_error[nn[k]], ++count;
      if (count == 0) continue;
      m.error[i] = static_cast<float>(sum / count);
      m.colors[i] = DivergingColor(sum / count / o.scale);
    }
  });
  size_t known = 0;
  for (float e : m.error) known += std::isfinite(e) ? 1 : 0;
  m.covered_fraction = m.vertices.empty() ? 0 : double(known) / m.vertices.size();
  return m;
}

void WriteErrorMeshPly(const ErrorMesh& m, const std::filesystem::path& path) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw Error(path.string() + ": cannot write");
  out << "ply\nformat binary_little_endian 1.0\ncomment fmv3d CAD model coloured by the comparison's error"
      << "\ncomment error: signed distance of the reconstruction, percent of H (NaN: no point near)\nelement vertex "
      << m.vertices.size()
      << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green"
         "\nproperty uchar blue\nproperty float error\nelement face "
      << m.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    const float xyz[3] = {static_cast<float>(m.vertices[i].x()), static_cast<float>(m.vertices[i].y()),
                          static_cast<float>(m.vertices[i].z())};
    out.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
    out.write(reinterpret_cast<const char*>(m.colors[i].data()), 3);
    const float e = 100.0f * m.error[i];
    out.write(reinterpret_cast<const char*>(&e), sizeof e);
  }
  for (const auto& t : m.triangles) {
    const uint8_t three = 3;
    out.write(reinterpret_cast<const char*>(&three), 1);
    out.write(reinterpret_cast<const char*>(t.data()), 12);
  }
  if (!out) throw Error(path.string() + ": write failed");
}

}  // namespace fmv3d::align
