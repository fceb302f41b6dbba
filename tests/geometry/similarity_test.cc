// The similarity module and the generic robust estimator on synthetic point sets with known answers.
#include "fmv3d/geometry/similarity.h"

#include <gtest/gtest.h>

#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/robust.h"

namespace fmv3d::geometry {
namespace {

core::Sim3 Truth() {
  core::Sim3 s;
  s.s = 2.5;
  s.q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()));
  s.t = Eigen::Vector3d(100, -40, 7);
  return s;
}

std::vector<Eigen::Vector3d> Cloud(int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 10);
  std::vector<Eigen::Vector3d> p;
  p.reserve(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) p.push_back({g(rng), g(rng), g(rng)});
  return p;
}

std::vector<Eigen::Vector3d> Apply(const core::Sim3& t, const std::vector<Eigen::Vector3d>& a) {
  std::vector<Eigen::Vector3d> b;
  b.reserve(a.size());
  for (const auto& x : a) b.push_back(t.Apply(x));
  return b;
}

TEST(Stats, MedianQuantileMeanRms) {
  EXPECT_EQ(core::Median({}), 0);
  EXPECT_EQ(core::Median({3, 1, 2}), 2);
  EXPECT_EQ(core::Median({4, 1, 3, 2}), 3);  // upper middle
  EXPECT_EQ(core::Quantile({5, 1, 4, 2, 3}, 0.0), 1);
  EXPECT_EQ(core::Quantile({5, 1, 4, 2, 3}, 1.0), 5);
  EXPECT_EQ(core::Quantile({5, 1, 4, 2, 3}, 0.6), 3);  // rank round(0.6·4) = 2
  EXPECT_EQ(core::Quantile({1, 2}, 7.0), 2);           // q clamped
  EXPECT_DOUBLE_EQ(core::Mean({1, 2, 6}), 3);
  EXPECT_DOUBLE_EQ(core::Rms({3, 4}), std::sqrt(12.5));
  EXPECT_DOUBLE_EQ(core::RobustSigma({1, 1, 1}), 1.4826);
}

// A 1D problem for the generic estimator: the model is a constant, a sample is one datum.
struct ConstantProblem {
  using Model = double;
  static constexpr int kSampleSize = 1;
  std::vector<double> data;
  size_t NumData() const { return data.size(); }
  bool Fit(const std::vector<size_t>& s, Model* m) const {
    *m = data[s[0]];
    return true;
  }
  double Residual(const Model& m, size_t i) const { return std::abs(data[i] - m); }
};

TEST(RobustEstimator, RansacAndLMedSFindTheMajority) {
  ConstantProblem p{{10.0, 10.1, 9.9, 10.05, 50, -20, 10.02}};
  RobustOptions o;
  o.max_residual = 0.2;
  o.exhaustive_up_to = 100;
  o.stop_when_all_inliers = false;
  const auto ransac = EstimateRobust(p, o);
  ASSERT_TRUE(ransac.found);
  EXPECT_EQ(ransac.num_inliers, 5u);
  EXPECT_EQ(ransac.inliers, (std::vector<char>{1, 1, 1, 1, 0, 0, 1}));
  EXPECT_EQ(ransac.samples_tried, 7);  // every 1-subset
  o.score = RobustOptions::Score::kLMedS;
  const auto lmeds = EstimateRobust(p, o);
  ASSERT_TRUE(lmeds.found);
  EXPECT_EQ(lmeds.model, 10.05);  // residuals 0, .03, .05, .05, .15, 30, 40: median 0.05, the smallest of the seven
  EXPECT_NEAR(lmeds.score, 0.05, 1e-12);
}

struct PairProblem {  // counts the samples it sees
  using Model = int;
  static constexpr int kSampleSize = 3;
  size_t n;
  mutable std::vector<std::vector<size_t>> seen;
  size_t NumData() const { return n; }
  bool Fit(const std::vector<size_t>& s, Model* m) const {
    seen.push_back(s);
    *m = 0;
    return false;
  }
  double Residual(const Model&, size_t) const { return 0; }
};

TEST(RobustEstimator, ExhaustiveThenRandomDistinctSamples) {
  PairProblem p{6, {}};
  RobustOptions o;
  o.score = RobustOptions::Score::kLMedS;
  o.exhaustive_up_to = 6;
  EXPECT_FALSE(EstimateRobust(p, o).found);
  EXPECT_EQ(p.seen.size(), 20u);  // C(6, 3)
  EXPECT_EQ(p.seen.front(), (std::vector<size_t>{0, 1, 2}));
  EXPECT_EQ(p.seen.back(), (std::vector<size_t>{3, 4, 5}));
  p.seen.clear();
  o.exhaustive_up_to = 5;
  o.max_iterations = 300;
  EstimateRobust(p, o);
  ASSERT_EQ(p.seen.size(), 300u);
  for (const auto& s : p.seen) {
    EXPECT_TRUE(s[0] != s[1] && s[0] != s[2] && s[1] != s[2]);
    for (size_t i : s) EXPECT_LT(i, 6u);
  }
  const auto first = p.seen;
  p.seen.clear();
  EstimateRobust(p, o);
  EXPECT_EQ(p.seen, first);  // deterministic for a seed
  o.max_residual = 0;
  o.score = RobustOptions::Score::kRansac;
  EXPECT_THROW(EstimateRobust(p, o), Error);
}

TEST(Similarity, WeightedAndRigid) {
  const core::Sim3 t = Truth();
  const auto a = Cloud(20, 1);
  std::vector<Eigen::Vector3d> b = Apply(t, a);
  core::Sim3 est;
  ASSERT_TRUE(EstimateSimilarity(a, b, &est));
  EXPECT_NEAR(est.s, t.s, 1e-12 * t.s);
  EXPECT_LT(core::RotationAngle(est.q, t.q), 1e-12);
  EXPECT_LT((est.t - t.t).norm(), 1e-9);
  // A gross outlier with zero weight changes nothing.
  auto b2 = b;
  b2[3] += Eigen::Vector3d(500, 0, 0);
  std::vector<double> w(a.size(), 1.0);
  w[3] = 0;
  ASSERT_TRUE(EstimateSimilarity(a, b2, w, true, &est));
  EXPECT_NEAR(est.s, t.s, 1e-12 * t.s);
  // Rigid: scale 1 on a rigidly moved set.
  core::Sim3 rigid = t;
  rigid.s = 1;
  const std::vector<Eigen::Vector3d> c = Apply(rigid, a);
  ASSERT_TRUE(EstimateSimilarity(a, c, {}, false, &est));
  EXPECT_EQ(est.s, 1.0);
  EXPECT_LT((est.t - rigid.t).norm(), 1e-9);
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}};
  EXPECT_FALSE(EstimateSimilarity(line, line, &est));
  EXPECT_FALSE(EstimateSimilarity(a, b, std::vector<double>(3, 1.0), true, &est));  // sizes differ
}

TEST(Similarity, AlongALineAndCollinearity) {
  const core::Sim3 t = Truth();
  std::vector<Eigen::Vector3d> a, b;
  for (int i = 0; i < 10; ++i) a.emplace_back(3.0 * i, 1.5 * i, -i), b.push_back(t.Apply(a.back()));
  EXPECT_NEAR(Collinearity(a), 0, 1e-9);
  EXPECT_NEAR(Collinearity({{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}}), 1, 1e-12);
  core::Sim3 est;
  ASSERT_TRUE(EstimateSimilarityAlongLine(a, b, &est));
  EXPECT_NEAR(est.s, t.s, 1e-9);
  for (size_t i = 0; i < a.size(); ++i) EXPECT_LT((est.Apply(a[i]) - b[i]).norm(), 1e-9);
  EXPECT_FALSE(EstimateSimilarityAlongLine({a[0], a[0]}, {b[0], b[0]}, &est));
}

TEST(Similarity, ScaleShiftUnderAHeldRotation) {
  const core::Sim3 t = Truth();
  const auto a = Cloud(8, 2);
  std::vector<Eigen::Vector3d> b = Apply(t, a);
  ScaleShift ss;
  ASSERT_TRUE(EstimateScaleShift(t.q.toRotationMatrix(), a, b, std::vector<double>(a.size(), 4.0), &ss));
  EXPECT_NEAR(ss.scale, t.s, 1e-12);
  EXPECT_LT((ss.translation - t.t).norm(), 1e-9);
  // Weights 1/σ² = 4: the translation's variance is σ²/n per axis about the centroid-weighted design.
  EXPECT_GT(ss.covariance(1, 1), 0);
  EXPECT_FALSE(EstimateScaleShift(t.q.toRotationMatrix(), {a[0], a[0]}, {b[0], b[0]}, {1.0, 1.0}, &ss));
}

TEST(Similarity, LMedSWithOutliersIsExact) {
  const core::Sim3 t = Truth();
  const auto a = Cloud(40, 3);
  std::vector<Eigen::Vector3d> b = Apply(t, a);
  for (size_t i = 0; i < 15; ++i) b[2 * i] += Eigen::Vector3d(30.0 + double(i), -20, 10);  // 37.5% gross outliers
  SimilarityLMedSOptions o;
  const SimilarityLMedS r = EstimateSimilarityLMedS(a, b, o);
  EXPECT_FALSE(r.along_line);
  EXPECT_NEAR(r.sim.s, t.s, 1e-9);
  EXPECT_LT(core::RotationAngle(r.sim.q, t.q), 1e-9);
  EXPECT_LT((r.sim.t - t.t).norm(), 1e-6);
  for (int i = 0; i < 40; ++i) EXPECT_EQ(r.inliers[i], !(i % 2 == 0 && i < 30)) << i;
  EXPECT_LT(r.sigma, 1e-9);
}

TEST(Similarity, LMedSSigmaFromGaussianNoise) {
  const core::Sim3 t = Truth();
  const auto a = Cloud(400, 4);
  std::mt19937_64 rng(9);
  std::normal_distribution<double> g(0, 0.5);
  std::vector<Eigen::Vector3d> b;
  b.reserve(a.size());
  for (const auto& x : a) b.push_back(t.Apply(x) + Eigen::Vector3d{g(rng), g(rng), g(rng)});
  const SimilarityLMedS r = EstimateSimilarityLMedS(a, b, {});
  EXPECT_NEAR(r.sigma, 0.5, 0.05);
  EXPECT_NEAR(r.sim.s, t.s, 0.01);
  size_t in = 0;
  for (char c : r.inliers) in += c;
  EXPECT_GE(in, 396u);  // 3.5σ holds 99.4% of a 3D Gaussian
}

TEST(Similarity, LMedSAlongAStraightTrack) {
  const core::Sim3 t = Truth();
  std::vector<Eigen::Vector3d> a, b;
  for (int i = 0; i < 20; ++i) a.emplace_back(i, 0, 0), b.push_back(t.Apply(a.back()));
  const SimilarityLMedS r = EstimateSimilarityLMedS(a, b, {});
  EXPECT_TRUE(r.along_line);
  EXPECT_NEAR(r.sim.s, t.s, 1e-9);
  for (size_t i = 0; i < a.size(); ++i) EXPECT_LT((r.sim.Apply(a[i]) - b[i]).norm(), 1e-9);
  EXPECT_THROW(EstimateSimilarityLMedS({a[0], a[1]}, {b[0], b[1]}, {}), Error);
  EXPECT_THROW(EstimateSimilarityLMedS({a[0], a[0], a[0]}, {b[0], b[1], b[2]}, {}), Error);
}

}  // namespace
}  // namespace fmv3d::geometry
