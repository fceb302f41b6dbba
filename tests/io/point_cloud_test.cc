#include "fmv3d/io/point_cloud.h"

#include <gtest/gtest.h>

#include <fstream>

#include "fmv3d/core/error.h"
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

}  // namespace
}  // namespace fmv3d::io
