#include "fmv3d/io/colmap_model.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

core::Reconstruction RandomModel() {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  core::Reconstruction rec;
  for (uint32_t c = 1; c <= 2; ++c) {
    core::Camera cam = core::Camera::Pinhole(1280 + c, 720, 1000 + 33.3 * U(rng));
    cam.id = c;
    cam.aspect = 1.0;  // COLMAP stores fx, fy: aspect = fx/fy round-trips exactly only when 1 or fx is exact
    cam.k1 = 0.1 * U(rng), cam.k2 = 0.01 * U(rng), cam.p1 = 1e-3 * U(rng), cam.p2 = 1e-3 * U(rng);
    cam.u0 += U(rng);
    rec.cameras[c] = cam;
  }
  for (uint32_t i = 1; i <= 5; ++i) {
    core::Image im;
    im.id = i;
    im.camera_id = 1 + i % 2;
    im.name = "flight-00000" + std::to_string(i) + ".png";
    im.pose = core::Pose::LookAt(Eigen::Vector3d{U(rng), U(rng), 10 + U(rng)} * 10, Eigen::Vector3d::Zero());
    for (int k = 0; k < 7; ++k) {
      im.points2d.push_back({640 + 600 * U(rng), 360 + 300 * U(rng)});
      im.point3d_ids.push_back(core::kNoPoint3D);
    }
    rec.images[i] = im;
  }
  for (uint64_t p = 1; p <= 7; ++p) {
    core::Point3D pt;
    pt.id = p;
    pt.xyz = Eigen::Vector3d{U(rng), U(rng), U(rng)} * 50;
    pt.rgb << p * 30, 255 - p, 7;
    pt.error = 0.1 * p;
    for (uint32_t i = 1; i <= 5; i += 2) {
      pt.track.push_back({i, static_cast<uint32_t>(p - 1)});
      rec.images[i].point3d_ids[p - 1] = p;
    }
    rec.points[p] = pt;
  }
  return rec;
}

TEST(ColmapModel, WriteReadIsIdentical) {
  test::TempDir dir;
  const auto rec = RandomModel();
  WriteColmapText(rec, dir / "a");
  const auto back = ReadColmapText(dir / "a");
  ASSERT_EQ(back.cameras.size(), rec.cameras.size());
  ASSERT_EQ(back.images.size(), rec.images.size());
  ASSERT_EQ(back.points.size(), rec.points.size());
  for (const auto& [id, c] : rec.cameras) EXPECT_EQ(back.cameras.at(id).Params(), c.Params());
  for (const auto& [id, im] : rec.images) {
    const auto& b = back.images.at(id);
    EXPECT_EQ(b.name, im.name);
    EXPECT_EQ(b.camera_id, im.camera_id);
    EXPECT_EQ(b.pose.q.coeffs(), im.pose.q.coeffs());
    EXPECT_EQ(b.pose.t, im.pose.t);
    EXPECT_EQ(b.points2d, im.points2d);
    EXPECT_EQ(b.point3d_ids, im.point3d_ids);
  }
  for (const auto& [id, p] : rec.points) {
    const auto& b = back.points.at(id);
    EXPECT_EQ(b.xyz, p.xyz);
    EXPECT_EQ(b.rgb, p.rgb);
    EXPECT_EQ(b.error, p.error);
    EXPECT_EQ(b.track, p.track);
  }
  // And the files themselves are a fixed point of write(read(.)).
  WriteColmapText(back, dir / "b");
  for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
    EXPECT_EQ(core::ReadTextFile(dir / "a" / f), core::ReadTextFile(dir / "b" / f)) << f;
}

TEST(ColmapModel, ClearErrors) {
  test::TempDir dir;
  EXPECT_THROW(ReadColmapText(dir / "missing"), Error);
  core::WriteTextFile(dir / "cameras.txt", "1 FISHEYE 100 100 1 2 3\n");
  core::WriteTextFile(dir / "images.txt", "");
  core::WriteTextFile(dir / "points3D.txt", "");
  try {
    ReadColmapText(dir.path());
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("FISHEYE"), std::string::npos);
  }
}

}  // namespace
}  // namespace fmv3d::io
