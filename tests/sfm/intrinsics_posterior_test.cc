// The posterior description of a camera's free intrinsics (DescribePosterior): σ, the 1σ displacement at the image
// corner, the weak flag, correlations and the least determined combination, from a given covariance, exactly.
#include <gtest/gtest.h>

#include <cmath>

#include "fmv3d/sfm/self_calibration.h"

namespace fmv3d::sfm {
namespace {

using Cov = Eigen::Matrix<double, core::kNumIntrinsics, core::kNumIntrinsics>;

core::Camera Orbit960() {
  core::Camera c;
  c.id = 1;
  c.width = 960;
  c.height = 540;
  c.f = 800;
  c.u0 = 492;
  c.v0 = 254;
  return c;
}

// The off-centre orbit's case (bench/results/pp11.md): the focal and v0 one weakly determined combination
// (σ 1.2 and 1.5 px, correlation −0.99), u0 well determined (0.02 px).
TEST(IntrinsicsPosterior, FocalAndV0TradingAlongOneLineAreWeak) {
  const core::Camera cam = Orbit960();
  Cov cov = Cov::Zero();
  cov(core::kF, core::kF) = 1.2 * 1.2;
  cov(core::kV0, core::kV0) = 1.5 * 1.5;
  cov(core::kF, core::kV0) = cov(core::kV0, core::kF) = -0.99 * 1.2 * 1.5;
  cov(core::kU0, core::kU0) = 0.02 * 0.02;
  const IntrinsicsPosterior p = DescribePosterior(cam, {core::kF, core::kU0, core::kV0}, &cov, 1.0);
  ASSERT_TRUE(p.determined);
  ASSERT_EQ(p.parameters.size(), 3u);
  // f: a unit change moves the corner (x, y) = (0.6, 0.3375) normalised by |(x, y)| pixels.
  const double corner_f = std::hypot(480.0 / 800, 270.0 / 800);
  EXPECT_DOUBLE_EQ(p.parameters[0].sigma, 1.2);
  EXPECT_NEAR(p.parameters[0].corner_sigma_px, 1.2 * corner_f, 1e-12);
  EXPECT_FALSE(p.parameters[0].weak);  // 0.83 px at the corner
  EXPECT_DOUBLE_EQ(p.parameters[1].sigma, 0.02);
  EXPECT_FALSE(p.parameters[1].weak);
  EXPECT_DOUBLE_EQ(p.parameters[2].sigma, 1.5);
  EXPECT_DOUBLE_EQ(p.parameters[2].corner_sigma_px, 1.5);
  EXPECT_TRUE(p.parameters[2].weak);
  EXPECT_TRUE(p.any_weak());
  EXPECT_NEAR(p.correlation(0, 2), -0.99, 1e-12);
  EXPECT_NEAR(p.correlation(0, 1), 0, 1e-12);
  // The least determined combination in corner pixels: the larger eigenvalue of [[a², ρab], [ρab, b²]] with
  // a = 1.2 · corner_f, b = 1.5, ρ = −0.99; v0 dominates it, with the focal of opposite sign.
  const double a = 1.2 * corner_f, b = 1.5, r = -0.99;
  const double mean = 0.5 * (a * a + b * b),
               half = std::sqrt(0.25 * std::pow(a * a - b * b, 2) + r * r * a * a * b * b);
  EXPECT_NEAR(p.weakest_corner_sigma_px, std::sqrt(mean + half), 1e-9);
  ASSERT_EQ(p.weakest_direction.size(), 3u);
  EXPECT_GT(p.weakest_direction[2], 0.5);
  EXPECT_LT(p.weakest_direction[0], 0);
  EXPECT_NEAR(p.weakest_direction[1], 0, 1e-9);
}

TEST(IntrinsicsPosterior, RankDeficientCovarianceIsNotDetermined) {
  const IntrinsicsPosterior p = DescribePosterior(Orbit960(), {core::kF, core::kU0, core::kV0}, nullptr, 1.0);
  EXPECT_FALSE(p.determined);
  EXPECT_TRUE(p.any_weak());
  ASSERT_EQ(p.parameters.size(), 3u);
  EXPECT_EQ(p.parameters[2].parameter, core::kV0);
  EXPECT_DOUBLE_EQ(p.parameters[2].value, 254);
}

TEST(IntrinsicsPosterior, FreeIntrinsicsFollowTheOptions) {
  BundleAdjustmentOptions o;  // focal, k1, k2
  EXPECT_EQ(FreeIntrinsics(o), (std::vector<core::IntrinsicIndex>{core::kF, core::kK1, core::kK2}));
  o.refine_principal_point = true;
  o.refine_k2 = false;
  EXPECT_EQ(FreeIntrinsics(o), (std::vector<core::IntrinsicIndex>{core::kF, core::kU0, core::kV0, core::kK1}));
}

}  // namespace
}  // namespace fmv3d::sfm
