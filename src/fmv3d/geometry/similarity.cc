#include "fmv3d/geometry/similarity.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::geometry {

bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        core::Sim3* sim) {
  const size_t n = src.size();
  if (n < 3 || dst.size() != n) return false;
  Eigen::Matrix3Xd a(3, n), b(3, n);
  for (size_t i = 0; i < n; ++i) {
    a.col(i) = src[i];
    b.col(i) = dst[i];
  }
  // Degenerate (collinear) sets: the second singular value of the centred source vanishes.
  const Eigen::Matrix3Xd ac = a.colwise() - a.rowwise().mean();
  Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(ac);
  const auto sv = svd.singularValues();
  if (!(sv(0) > 0) || sv(1) < 1e-9 * sv(0)) return false;
  const Eigen::Matrix4d T = Eigen::umeyama(a, b, true);
  if (!T.allFinite()) return false;
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  const double s = std::cbrt(sR.determinant());
  if (!(s > 0)) return false;
  sim->s = s;
  sim->q = Eigen::Quaterniond(sR / s).normalized();
  sim->t = T.topRightCorner<3, 1>();
  return true;
}

void SimilarityRansacOptions::Check() const {
  if (!(max_error > 0)) throw Error("similarity RANSAC: max_error must be > 0");
  if (max_iterations < 1) throw Error("similarity RANSAC: max_iterations must be ≥ 1");
}

int EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                             const SimilarityRansacOptions& options, core::Sim3* sim,
                             std::vector<char>* inlier_mask) {
  options.Check();
  const size_t n = src.size();
  if (n < 3 || dst.size() != n) return 0;
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  const double thr2 = options.max_error * options.max_error;
  auto count = [&](const core::Sim3& s, std::vector<char>* mask) {
    int c = 0;
    if (mask) mask->assign(n, 0);
    for (size_t i = 0; i < n; ++i)
      if ((s.Apply(src[i]) - dst[i]).squaredNorm() < thr2) {
        ++c;
        if (mask) (*mask)[i] = 1;
      }
    return c;
  };
  int best = 0;
  core::Sim3 best_sim;
  for (int it = 0; it < options.max_iterations; ++it) {
    size_t i0 = pick(rng), i1 = pick(rng), i2 = pick(rng);
    if (i0 == i1 || i0 == i2 || i1 == i2) continue;
    core::Sim3 s;
    if (!EstimateSimilarity({src[i0], src[i1], src[i2]}, {dst[i0], dst[i1], dst[i2]}, &s)) continue;
    const int c = count(s, nullptr);
    if (c > best) {
      best = c;
      best_sim = s;
      if (best == static_cast<int>(n)) break;
    }
  }
  if (best < 3) return 0;
  // Least squares on the inliers, then re-count (twice, so the final inlier set matches the final model).
  std::vector<char> mask;
  for (int round = 0; round < 2; ++round) {
    count(best_sim, &mask);
    std::vector<Eigen::Vector3d> a, b;
    for (size_t i = 0; i < n; ++i)
      if (mask[i]) {
        a.push_back(src[i]);
        b.push_back(dst[i]);
      }
    core::Sim3 refined;
    if (EstimateSimilarity(a, b, &refined) && count(refined, nullptr) >= static_cast<int>(a.size()))
      best_sim = refined;
  }
  *sim = best_sim;
  const int c = count(best_sim, &mask);
  if (inlier_mask) *inlier_mask = mask;
  return c;
}

}  // namespace fmv3d::geometry
