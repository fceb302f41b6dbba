// Pieces the cameras see through: a ground plane, a real roof (the ground under it hidden from every camera whose
// ray it blocks) and a blob floating over ground that the cameras measured, seen from nine cameras above.
#include "fmv3d/surface/free_space.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "fmv3d/core/error.h"

namespace fmv3d::surface {
namespace {

// A flat square patch [x0, x1] × [y0, y1] at height z, `step` apart, appended to the mesh.
void AddPatch(ColoredMesh* m, double x0, double x1, double y0, double y1, double z, double step) {
  const int nx = static_cast<int>(std::lround((x1 - x0) / step)) + 1,
            ny = static_cast<int>(std::lround((y1 - y0) / step)) + 1;
  const int base = static_cast<int>(m->vertices.size());
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) m->vertices.emplace_back(x0 + i * step, y0 + j * step, z);
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int a = base + j * nx + i;
      m->triangles.emplace_back(a, a + 1, a + nx + 1);
      m->triangles.emplace_back(a, a + nx + 1, a + nx);
    }
}

struct Scene {
  ColoredMesh mesh;
  io::OrientedPointCloud cloud;
  std::map<uint32_t, FreeSpaceView> views;
};

bool InRoof(double x, double y) { return x >= 5 && x <= 7 && y >= 5 && y <= 7; }

Scene MakeScene() {
  Scene s;
  // Nine nadir cameras 30 m up: camera x = world x, camera y = −world y, looking down.
  const Eigen::Matrix3d R = Eigen::Vector3d(1, -1, -1).asDiagonal();
  uint32_t id = 1;
  for (double cx : {-8.0, 0.0, 8.0})
    for (double cy : {-8.0, 0.0, 8.0}) {
      FreeSpaceView v;
      v.camera = core::Camera::Pinhole(400, 300, 300);
      v.pose.q = Eigen::Quaterniond(R);
      v.pose.t = -(R * Eigen::Vector3d(cx, cy, 30));
      s.views[id++] = v;
    }
  AddPatch(&s.mesh, -10, 10, -10, 10, 0, 0.25);  // ground
  AddPatch(&s.mesh, 5, 7, 5, 7, 5, 0.25);        // roof
  AddPatch(&s.mesh, -1, 1, -1, 1, 5, 0.25);      // blob
  const size_t mesh_faces = s.mesh.triangles.size();
  EXPECT_GT(mesh_faces, 0u);
  // Ground points, each seen by the cameras whose ray to it the roof does not block (the blob blocks nothing).
  auto add = [&](const Eigen::Vector3d& p, const std::vector<uint32_t>& vis) {
    if (vis.empty()) return;
    s.cloud.positions.push_back(p);
    s.cloud.visibility.push_back(vis);
  };
  for (int j = 0; j <= 200; ++j)
    for (int i = 0; i <= 200; ++i) {
      const Eigen::Vector3d p(-10 + 0.1 * i, -10 + 0.1 * j, 0);
      std::vector<uint32_t> vis;
      for (const auto& [vid, v] : s.views) {
        const Eigen::Vector3d c = v.pose.q.conjugate() * (-v.pose.t);  // centre
        const Eigen::Vector3d at5 = p + (c - p) * (5.0 / c.z());       // the ray at the roof's height
        if (!InRoof(at5.x(), at5.y())) vis.push_back(vid);
      }
      add(p, vis);
    }
  std::vector<uint32_t> all;
  for (const auto& [vid, v] : s.views) all.push_back(vid);
  for (int j = 0; j <= 20; ++j)
    for (int i = 0; i <= 20; ++i) {
      add({5 + 0.1 * i, 5 + 0.1 * j, 5}, all);    // roof
      add({-1 + 0.1 * i, -1 + 0.1 * j, 5}, all);  // blob: outlier points that fusion let through
    }
  return s;
}

TEST(FreeSpace, BlobOverMeasuredGroundIsDroppedRoofIsKept) {
  Scene s = MakeScene();
  const size_t blob_faces = size_t{2} * 8 * 8;
  const size_t faces = s.mesh.triangles.size();
  const FreeSpaceStats st = DropPiecesInFreeSpace(&s.mesh, s.cloud, s.views);
  EXPECT_EQ(st.pieces, 3u);
  EXPECT_EQ(st.tested, 2u);
  EXPECT_EQ(st.dropped, 1u);
  EXPECT_EQ(st.faces_dropped, blob_faces);
  EXPECT_EQ(s.mesh.triangles.size(), faces - blob_faces);
  // What is left: the ground and the roof, nothing near the blob's height over the origin.
  size_t roof_vertices = 0;
  for (const auto& v : s.mesh.vertices) {
    EXPECT_FALSE(v.z() > 4 && v.head<2>().norm() < 2) << v.transpose();
    roof_vertices += v.z() > 4 && InRoof(v.x(), v.y());
  }
  EXPECT_EQ(roof_vertices, 9u * 9u);
  s.mesh.Validate();
}

// The blob aliased alike in all nine views while one camera measured the ground around and behind it: its own
// pairs outnumber the ground's about six to one (share 0.15), and it is still seen through.
TEST(FreeSpace, BlobFromMoreViewsThanTheGroundBehindItIsDropped) {
  Scene s = MakeScene();
  size_t thinned = 0;
  for (size_t i = 0; i < s.cloud.size(); ++i) {
    const Eigen::Vector3d& p = s.cloud.positions[i];
    if (p.z() < 1 && std::abs(p.x()) <= 3 && std::abs(p.y()) <= 3 && s.cloud.visibility[i].size() > 2) {
      s.cloud.visibility[i] = {5};
      ++thinned;
    }
  }
  EXPECT_GT(thinned, 3000u);
  const FreeSpaceStats st = DropPiecesInFreeSpace(&s.mesh, s.cloud, s.views);
  EXPECT_EQ(st.dropped, 1u);
  EXPECT_EQ(st.faces_dropped, size_t{2} * 8 * 8);
  // At the old share of a quarter it stood.
  Scene again = MakeScene();
  for (size_t i = 0; i < again.cloud.size(); ++i) {
    const Eigen::Vector3d& p = again.cloud.positions[i];
    if (p.z() < 1 && std::abs(p.x()) <= 3 && std::abs(p.y()) <= 3) again.cloud.visibility[i] = {5};
  }
  FreeSpaceOptions quarter;
  quarter.max_through_share = 0.25;
  EXPECT_EQ(DropPiecesInFreeSpace(&again.mesh, again.cloud, again.views, quarter).dropped, 0u);
}

TEST(FreeSpace, NothingDroppedWithoutTheCamerasOrWithOnePiece) {
  Scene s = MakeScene();
  const size_t faces = s.mesh.triangles.size();
  EXPECT_EQ(DropPiecesInFreeSpace(&s.mesh, s.cloud, {}).dropped, 0u);
  EXPECT_EQ(s.mesh.triangles.size(), faces);
  ColoredMesh ground;
  AddPatch(&ground, -10, 10, -10, 10, 0, 1);
  EXPECT_EQ(DropPiecesInFreeSpace(&ground, s.cloud, s.views).tested, 0u);
  io::OrientedPointCloud no_visibility;
  no_visibility.positions = s.cloud.positions;
  EXPECT_THROW(DropPiecesInFreeSpace(&s.mesh, no_visibility, s.views), Error);
  FreeSpaceOptions bad;
  bad.margin = 0;
  EXPECT_THROW(DropPiecesInFreeSpace(&s.mesh, s.cloud, s.views, bad), Error);
}

}  // namespace
}  // namespace fmv3d::surface
