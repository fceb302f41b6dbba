#include "fmv3d/io/ground_truth.h"

#include <gtest/gtest.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

TEST(GroundTruth, StrechaFountainCentresMatchTheFiles) {
  FMV3D_REQUIRE_SHARED_DATA("mvs/fountain-P11/gt_dense_cameras");
  const auto rec = ReadStrechaCameras(test::SharedData() / "mvs/fountain-P11/gt_dense_cameras");
  ASSERT_EQ(rec.images.size(), 11u);
  EXPECT_EQ(rec.cameras.size(), 1u);  // one physical camera
  const auto* im = rec.FindImageByName("0000.jpg");
  ASSERT_NE(im, nullptr);
  EXPECT_TRUE(im->pose.Centre().isApprox(Eigen::Vector3d(-7.28137, -7.57667, 0.204446), 1e-9));
  const auto& cam = rec.cameras.at(im->camera_id);
  EXPECT_EQ(cam.width, 3072);
  EXPECT_NEAR(cam.f, 2764.16, 1e-9);
  EXPECT_NEAR(cam.u0, 1520.69 + 0.5, 1e-9);
}

TEST(GroundTruth, MiddleburyTempleProjectsConsistently) {
  FMV3D_REQUIRE_SHARED_DATA("mvs/middlebury/templeRing/templeR_par.txt");
  const auto rec = ReadMiddleburyPar(test::SharedData() / "mvs/middlebury/templeRing/templeR_par.txt");
  ASSERT_GE(rec.images.size(), 19u);
  // The temple sits near the origin inside a ~0.2 m box: every camera sees the origin in front of it, in frame.
  for (const auto& [id, im] : rec.images) {
    const Eigen::Vector3d x = im.pose.Transform(Eigen::Vector3d(-0.02, 0.05, 0.0));
    ASSERT_GT(x.z(), 0) << im.name;
    EXPECT_TRUE(rec.cameras.at(im.camera_id).InImage(rec.cameras.at(im.camera_id).Project(x))) << im.name;
  }
}

TEST(GroundTruth, KrtdNamesFollowOurFrameConvention) {
  test::TempDir dir;
  core::WriteTextFile(dir / "clip-00001.krtd",
                      "1000 0 180\n0 1000 120\n0 0 1\n\n1 0 0\n0 1 0\n0 0 1\n\n0 0 5\n\n-0.1 0.01\n");
  const auto rec = ReadKrtdFolder(dir.path(), 360, 240);
  ASSERT_EQ(rec.images.size(), 1u);
  EXPECT_EQ(rec.images.begin()->second.name, "clip-000000.png");
  EXPECT_DOUBLE_EQ(rec.cameras.begin()->second.k1, -0.1);
  EXPECT_THROW(ReadKrtdFolder(dir / "nope", 360, 240), Error);
}

}  // namespace
}  // namespace fmv3d::io
