#include "fmv3d/io/point_cloud.h"

#include <gtest/gtest.h>

#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/io/ply_mesh.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

TEST(PointCloudPly, RoundTripKeepsEveryAttribute) {
  test::TempDir dir;
  OrientedPointCloud c;
  for (int i = 0; i < 100; ++i) {
    c.positions.emplace_back(i * 0.5, -i, 3.25);
    c.normals.emplace_back(0, 0, 1);
    c.colors.push_back(Rgb8(i, 255 - i, 7));
    c.visibility.push_back(std::vector<uint32_t>(i % 5, static_cast<uint32_t>(i)));
  }
  WritePointCloudPly(c, dir / "c.ply");
  const auto r = ReadPointCloudPly(dir / "c.ply");
  ASSERT_EQ(r.size(), 100u);
  ASSERT_TRUE(r.has_normals() && r.has_colors() && r.has_visibility());
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(r.positions[i], c.positions[i]);
    EXPECT_EQ(r.colors[i], c.colors[i]);
    EXPECT_EQ(r.visibility[i], c.visibility[i]);
  }
}

TEST(PointCloudPly, ReadsAsciiWithoutOptionalAttributes) {
  test::TempDir dir;
  std::ofstream(dir / "a.ply") << "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\n"
                                  "property double y\nproperty double z\nend_header\n1 2 3\n4 5 6\n";
  const auto r = ReadPointCloudPly(dir / "a.ply");
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r.positions[1], Eigen::Vector3d(4, 5, 6));
  EXPECT_FALSE(r.has_normals());
}

TEST(PointCloudPly, TruncatedFileIsAClearError) {
  test::TempDir dir;
  std::ofstream(dir / "t.ply") << "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
                                  "property float y\nproperty float z\nend_header\n1234";
  try {
    ReadPointCloudPly(dir / "t.ply");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos);
  }
  EXPECT_THROW(ReadPointCloudPly(dir / "missing.ply"), Error);
}

TEST(PointCloudPly, AnElementDeclaredTwiceIsAClearError) {
  // Found by ply_fuzz: the second vertex element (no normals) was read over the first (with normals), and its
  // normals were taken from column −1.
  test::TempDir dir;
  std::ofstream(dir / "twice.ply") << "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                      "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
                                      "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                                      "end_header\n0 0 0 0 0 1\n1 1 1\n";
  for (auto read : {+[](const std::filesystem::path& p) { ReadPointCloudPly(p); },
                    +[](const std::filesystem::path& p) { ReadMeshPly(p); }}) {
    try {
      read(dir / "twice.ply");
      ADD_FAILURE();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("element 'vertex' declared twice"), std::string::npos) << e.what();
    }
  }
}

// An ascii mesh with a quad, a triangle and float colours, as other tools write it.
const char* kQuadMesh =
    "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
    "property float red\nproperty float green\nproperty float blue\n"
    "element face 2\nproperty list uchar uint vertex_indices\nend_header\n"
    "0 0 0 1 0 0\n1 0 0 0 1 0\n1 1 0 0 0 1\n0 1 0 1 1 1\n0 0 1 0.5 0.5 0.5\n";

TEST(MeshPly, PolygonsBecomeTriangleFans) {
  test::TempDir dir;
  std::ofstream(dir / "m.ply") << kQuadMesh << "4 0 1 2 3\n3 0 1 4\n";
  const PlyMesh m = ReadMeshPly(dir / "m.ply");
  ASSERT_EQ(m.vertices.size(), 5u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(0, 1, 2));
  EXPECT_EQ(m.triangles[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_EQ(m.triangles[2], Eigen::Vector3i(0, 1, 4));
  ASSERT_TRUE(m.vertices.has_colors());
  EXPECT_EQ(m.vertices.colors[1], Rgb8(0, 255, 0));
  EXPECT_EQ(m.vertices.colors[4], Rgb8(128, 128, 128));
}

TEST(MeshPly, RoundTripOfOurPointCloudHasNoTriangles) {
  test::TempDir dir;
  OrientedPointCloud c;
  c.positions = {{0, 0, 0}, {1, 0, 0}};
  WritePointCloudPly(c, dir / "c.ply");
  const PlyMesh m = ReadMeshPly(dir / "c.ply");
  EXPECT_EQ(m.vertices.size(), 2u);
  EXPECT_TRUE(m.triangles.empty());
}

// A face naming a vertex past the end, a negative one, or fewer than three: an error naming the face, never an
// index handed on (Open3D's reader crashed on such a polygon).
TEST(MeshPly, BadFacesAreClearErrors) {
  test::TempDir dir;
  const std::pair<const char*, const char*> cases[] = {
      {"4 0 1 2 9\n3 0 1 4\n", "names a vertex that does not exist"},
      {"3 0 1 2\n3 0 -1 4\n", "names a vertex that does not exist"},
      {"3 0 1 2\n2 0 1\n", "fewer than 3 vertices"},
      {"3 0 1 2\n", "truncated"},
  };
  for (const auto& [faces, message] : cases) {
    std::ofstream(dir / "bad.ply") << kQuadMesh << faces;
    try {
      ReadMeshPly(dir / "bad.ply");
      ADD_FAILURE() << faces;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
    }
  }
  std::ofstream(dir / "nofaces.ply")
      << "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
         "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
         "end_header\n3 0 1 2\n0 0 0\n1 0 0\n0 1 0\n";
  EXPECT_THROW(ReadMeshPly(dir / "nofaces.ply"), Error);
}

}  // namespace
}  // namespace fmv3d::io
