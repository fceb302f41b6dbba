#include "fmv3d/surface/free_space.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "fmv3d/core/error.h"
#include "fmv3d/surface/mesh_cleanup.h"

namespace fmv3d::surface {
namespace {

// The nearest tested piece per footprint cell of one camera.
struct Footprint {
  int width = 0, height = 0;
  std::vector<float> depth;
  std::vector<int> piece;  // -1: none
  // The piece at a cell whose four neighbours show the same piece (the footprint eroded by one cell, so that
  // points beside a piece's silhouette do not count as seen through it); -1 otherwise.
  int InteriorPiece(int x, int y) const {
    const int p = piece[y * width + x];
    if (p < 0 || x == 0 || y == 0 || x + 1 >= width || y + 1 >= height) return -1;
    const int i = y * width + x;
    return piece[i - 1] == p && piece[i + 1] == p && piece[i - width] == p && piece[i + width] == p ? p : -1;
  }
};

}  // namespace

void FreeSpaceOptions::Check() const {
  if (!(footprint_scale > 0 && footprint_scale <= 1)) throw Error("free space: footprint scale must be in (0, 1]");
  if (!(margin > 0 && margin < 1)) throw Error("free space: margin must be in (0, 1)");
  if (!(max_through_share > 0 && max_through_share <= 1)) throw Error("free space: share must be in (0, 1]");
}

FreeSpaceStats DropPiecesInFreeSpace(ColoredMesh* mesh, const io::OrientedPointCloud& cloud,
                                     const std::map<uint32_t, FreeSpaceView>& views, const FreeSpaceOptions& o) {
  o.Check();
  mesh->Validate();
  if (!cloud.has_visibility()) throw Error("free space: the point cloud has no visibility lists");
  FreeSpaceStats st;
  const MeshPieces pieces = FindPieces(mesh->vertices, mesh->triangles);
  const std::vector<double>& area = pieces.area;
  const std::vector<int> piece_of = pieces.VertexPieces(mesh->triangles, mesh->vertices.size());
  st.pieces = area.size();
  if (area.size() < 2) return st;
  const int largest = static_cast<int>(std::max_element(area.begin(), area.end()) - area.begin());
  st.tested = area.size() - 1;

  std::vector<uint32_t> tested;  // the vertices drawn into the footprints: those of every piece but the largest
  for (size_t v = 0; v < piece_of.size(); ++v)
    if (piece_of[v] >= 0 && piece_of[v] != largest) tested.push_back(static_cast<uint32_t>(v));
  std::map<uint32_t, std::vector<uint32_t>> seen_by;  // camera → the points it saw
  for (size_t i = 0; i < cloud.size(); ++i)
    for (uint32_t id : cloud.visibility[i])
      if (views.count(id)) seen_by[id].push_back(static_cast<uint32_t>(i));

  std::vector<double> through(area.size(), 0), on(area.size(), 0);
  Footprint fp;
  for (const auto& entry : views) {
    const FreeSpaceView& view = entry.second;  // named, not a structured binding: the lambda below captures it
    const auto seen = seen_by.find(entry.first);
    if (seen == seen_by.end()) continue;
    fp.width = std::max(1, static_cast<int>(std::lround(view.camera.width * o.footprint_scale)));
    fp.height = std::max(1, static_cast<int>(std::lround(view.camera.height * o.footprint_scale)));
    fp.depth.assign(static_cast<size_t>(fp.width) * fp.height, std::numeric_limits<float>::infinity());
    fp.piece.assign(fp.depth.size(), -1);
    // Cell of a world point in this camera, and its depth; false when behind or outside.
    auto cell_of = [&](const Eigen::Vector3d& X, int* x, int* y, double* z) {
      const Eigen::Vector3d c = view.pose.Transform(X);
      if (!(c.z() > 0)) return false;
      const Eigen::Vector2d uv = view.camera.Project(c) * o.footprint_scale;
      if (!(uv.x() >= 0 && uv.y() >= 0 && uv.x() < fp.width && uv.y() < fp.height)) return false;
      *x = static_cast<int>(uv.x()), *y = static_cast<int>(uv.y()), *z = c.z();
      return true;
    };
    bool any = false;
    for (uint32_t v : tested) {
      int x, y;
      double z;
      if (!cell_of(mesh->vertices[v], &x, &y, &z)) continue;
      const size_t i = static_cast<size_t>(y) * fp.width + x;
      if (z < fp.depth[i]) fp.depth[i] = static_cast<float>(z), fp.piece[i] = piece_of[v], any = true;
    }
    if (!any) continue;
    for (uint32_t i : seen->second) {
      int x, y;
      double z;
      if (!cell_of(cloud.positions[i], &x, &y, &z)) continue;
      const int p = fp.InteriorPiece(x, y);
      if (p < 0) continue;
      const double d = fp.depth[static_cast<size_t>(y) * fp.width + x];
      if (z > d * (1 + o.margin))
        ++through[p];
      else if (z >= d * (1 - o.margin))
        ++on[p];
    }
  }

  std::vector<bool> drop(area.size(), false);
  for (size_t p = 0; p < area.size(); ++p) {
    if (static_cast<int>(p) == largest) continue;
    drop[p] = through[p] >= o.min_through_pairs && through[p] > o.max_through_share * (through[p] + on[p]);
    st.dropped += drop[p];
    spdlog::debug("free space: piece {} (area {:.4g}): {:.0f} pairs through, {:.0f} on{}", p, area[p], through[p],
                  on[p], drop[p] ? ": dropped" : "");
  }
  if (st.dropped == 0) return st;

  ColoredMesh kept;
  std::vector<int> remap(mesh->vertices.size(), -1);
  for (const auto& f : mesh->triangles) {
    if (drop[piece_of[f[0]]]) {
      ++st.faces_dropped;
      continue;
    }
    Eigen::Vector3i g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[f[k]];
      if (r < 0) {
        r = static_cast<int>(kept.vertices.size());
        kept.vertices.push_back(mesh->vertices[f[k]]);
        if (!mesh->normals.empty()) kept.normals.push_back(mesh->normals[f[k]]);
        if (!mesh->colors.empty()) kept.colors.push_back(mesh->colors[f[k]]);
      }
      g[k] = r;
    }
    kept.triangles.push_back(g);
  }
  *mesh = std::move(kept);
  return st;
}

}  // namespace fmv3d::surface
