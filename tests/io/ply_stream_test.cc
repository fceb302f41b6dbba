// Streaming PLY vertices (io/ply_stream.h) gives what the whole-cloud reader gives, lists skipped.
#include "fmv3d/io/ply_stream.h"

#include <gtest/gtest.h>

#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/io/point_cloud.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

TEST(PlyStream, MatchesTheWholeCloudReaderAndSkipsVisibilityLists) {
  test::TempDir tmp("plystream");
  OrientedPointCloud cloud;
  for (int i = 0; i < 1000; ++i) {
    cloud.positions.emplace_back(0.5 * i, -0.25 * i, 3 + i % 7);
    cloud.normals.push_back(Eigen::Vector3f(1, i % 3, 2).normalized());
    cloud.colors.emplace_back(uint8_t(i), uint8_t(i / 4), uint8_t(200));
    cloud.visibility.push_back(std::vector<uint32_t>(i % 5, static_cast<uint32_t>(i)));
    cloud.sigma.push_back(0.001f * (1 + i % 11));
  }
  WritePointCloudPly(cloud, tmp / "c.ply");
  const OrientedPointCloud whole = ReadPointCloudPly(tmp / "c.ply");
  size_t announced = 0, i = 0;
  ASSERT_TRUE(StreamPlyVertices(
      tmp / "c.ply", [&](size_t n) { announced = n; },
      [&](const PlyVertex& v) {
        ASSERT_LT(i, whole.size());
        EXPECT_EQ(v.position, whole.positions[i].cast<float>());
        EXPECT_EQ(v.normal, whole.normals[i]);
        EXPECT_EQ(v.rgb[0], whole.colors[i][0]);
        EXPECT_EQ(v.rgb[2], whole.colors[i][2]);
        EXPECT_EQ(v.views, whole.visibility[i].size());
        EXPECT_EQ(v.sigma, whole.sigma[i]);
        ++i;
      }));
  EXPECT_EQ(announced, 1000u);
  EXPECT_EQ(i, 1000u);
}

TEST(PlyStream, AsciiIsLeftToTheWholeReaderAndTruncationIsAnError) {
  test::TempDir tmp("plystream");
  std::ofstream(tmp / "a.ply") << "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                  "property float z\nend_header\n1 2 3\n";
  EXPECT_FALSE(StreamPlyVertices(tmp / "a.ply", nullptr, [](const PlyVertex&) {}));
  std::ofstream(tmp / "t.ply", std::ios::binary)
      << "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nend_header\n"
      << std::string(20, '\0');
  EXPECT_THROW(StreamPlyVertices(tmp / "t.ply", nullptr, [](const PlyVertex&) {}), Error);
  EXPECT_THROW(StreamPlyVertices(tmp / "missing.ply", nullptr, [](const PlyVertex&) {}), Error);
}

}  // namespace
}  // namespace fmv3d::io
