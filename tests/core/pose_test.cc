#include "fmv3d/core/pose.h"

#include <gtest/gtest.h>

#include <random>

namespace fmv3d::core {
namespace {

TEST(Pose, OmegaPhiKappaRoundTrip) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> U(-M_PI, M_PI), H(-M_PI / 2 + 1e-3, M_PI / 2 - 1e-3);
  for (int i = 0; i < 1000; ++i) {
    const double w = U(rng), p = H(rng), k = U(rng);
    const Eigen::Vector3d opk = OmegaPhiKappaFromRotation(RotationFromOmegaPhiKappa(w, p, k));
    EXPECT_NEAR(opk[0], w, 1e-9);
    EXPECT_NEAR(opk[1], p, 1e-9);
    EXPECT_NEAR(opk[2], k, 1e-9);
  }
}

TEST(Pose, OmegaPhiKappaIsZYXAboutMovingAxes) {
  // R = Rz(κ)·Ry(φ)·Rx(ω): a pure ω turns y towards z.
  const Eigen::Matrix3d R = RotationFromOmegaPhiKappa(M_PI / 2, 0, 0);
  EXPECT_TRUE((R * Eigen::Vector3d::UnitY()).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  const Eigen::Matrix3d R2 = RotationFromOmegaPhiKappa(0.1, 0.2, 0.3);
  const Eigen::Matrix3d expect = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                 Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                                 Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_TRUE(R2.isApprox(expect, 1e-14));
  // Gimbal lock still returns a rotation that reproduces R.
  const Eigen::Matrix3d L = RotationFromOmegaPhiKappa(0.4, M_PI / 2, 0.9);
  const Eigen::Vector3d opk = OmegaPhiKappaFromRotation(L);
  EXPECT_TRUE(RotationFromOmegaPhiKappa(opk[0], opk[1], opk[2]).isApprox(L, 1e-9));
}

TEST(Pose, CentreAndLookAt) {
  const Eigen::Vector3d C(10, -5, 30), target(1, 2, 0);
  const Pose p = Pose::LookAt(C, target);
  EXPECT_TRUE(p.Centre().isApprox(C, 1e-12));
  const Eigen::Vector3d xt = p.Transform(target);
  EXPECT_NEAR(xt.x(), 0, 1e-9);
  EXPECT_NEAR(xt.y(), 0, 1e-9);
  EXPECT_GT(xt.z(), 0);
  // World up (+z) appears towards the top of the image (−y).
  EXPECT_LT(p.Transform(target + Eigen::Vector3d::UnitZ()).y(), 0);
}

TEST(Pose, Sim3MovesCamerasWithTheWorld) {
  Sim3 s;
  s.s = 2.5;
  s.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
  s.t = Eigen::Vector3d(4, -1, 2);
  const Pose p = Pose::LookAt(Eigen::Vector3d(3, 4, 5), Eigen::Vector3d::Zero());
  const Eigen::Vector3d X(0.3, -0.2, 0.1);
  const Pose p2 = s.Apply(p);
  EXPECT_TRUE(p2.Centre().isApprox(s.Apply(p.Centre()), 1e-12));
  // Same point, same image direction after transforming both.
  const Eigen::Vector3d a = p.Transform(X), b = p2.Transform(s.Apply(X));
  EXPECT_TRUE((b / b.z()).isApprox(a / a.z(), 1e-12));
  const Sim3 inv = s.Inverse();
  EXPECT_TRUE(inv.Apply(s.Apply(X)).isApprox(X, 1e-12));
}

}  // namespace
}  // namespace fmv3d::core
