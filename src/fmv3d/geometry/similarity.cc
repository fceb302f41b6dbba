#include "fmv3d/geometry/similarity.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/robust.h"

namespace fmv3d::geometry {
namespace {

Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& p) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& x : p) c += x;
  return c / static_cast<double>(std::max<size_t>(1, p.size()));
}

Eigen::Matrix3d Scatter(const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3d& c) {
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& x : p) cov += (x - c) * (x - c).transpose();
  return cov;
}

// Minimal-sample problems for geometry/robust.h.
struct SimilarityProblem {
  using Model = core::Sim3;
  static constexpr int kSampleSize = 3;
  const std::vector<Eigen::Vector3d>& src;
  const std::vector<Eigen::Vector3d>& dst;
  bool along_line = false;
  size_t NumData() const { return src.size(); }
  bool Fit(const std::vector<size_t>& s, Model* m) const {
    const std::vector<Eigen::Vector3d> a = {src[s[0]], src[s[1]], src[s[2]]};
    const std::vector<Eigen::Vector3d> b = {dst[s[0]], dst[s[1]], dst[s[2]]};
    if (!(along_line ? EstimateSimilarityAlongLine(a, b, m) : EstimateSimilarity(a, b, m))) return false;
    return m->s > 0 && std::isfinite(m->s);
  }
  double Residual(const Model& m, size_t i) const { return (m.Apply(src[i]) - dst[i]).norm(); }
};

}  // namespace

bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        const std::vector<double>& weights, bool estimate_scale, core::Sim3* sim) {
  const size_t n = src.size();
  if (n < 3 || dst.size() != n || (!weights.empty() && weights.size() != n)) return false;
  const auto weight = [&](size_t i) { return weights.empty() ? 1.0 : weights[i]; };
  double wsum = 0;
  Eigen::Vector3d ms = Eigen::Vector3d::Zero(), md = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    wsum += weight(i);
    ms += weight(i) * src[i];
    md += weight(i) * dst[i];
  }
  if (!(wsum > 0)) return false;
  ms /= wsum;
  md /= wsum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero(), scatter = Eigen::Matrix3d::Zero();
  double var_s = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = src[i] - ms, b = dst[i] - md;
    cov += weight(i) * b * a.transpose();
    scatter += weight(i) * a * a.transpose();
    var_s += weight(i) * a.squaredNorm();
  }
  cov /= wsum;
  var_s /= wsum;
  if (!(var_s > 0)) return false;
  // A collinear source leaves the rotation about its line free: its second principal spread vanishes.
  const Eigen::Vector3d spread = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvalues();
  if (!(spread(1) > 1e-18 * spread(2))) return false;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv[1] > 1e-12 * std::max(sv[0], 1e-300))) return false;
  Eigen::Matrix3d S = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) S(2, 2) = -1;
  const Eigen::Matrix3d R = svd.matrixU() * S * svd.matrixV().transpose();
  const double s = estimate_scale ? (sv.asDiagonal() * S).trace() / var_s : 1.0;
  if (!(s > 0) || !std::isfinite(s) || !R.allFinite()) return false;
  sim->s = s;
  sim->q = Eigen::Quaterniond(R).normalized();
  sim->t = md - s * (R * ms);
  return true;
}

bool EstimateSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                        core::Sim3* sim) {
  return EstimateSimilarity(src, dst, {}, true, sim);
}

bool EstimateSimilarityAlongLine(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                                 core::Sim3* sim) {
  const size_t n = src.size();
  if (n < 2 || dst.size() != n) return false;
  const Eigen::Vector3d cs = Centroid(src), cd = Centroid(dst);
  const auto axis = [](const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3d& c) {
    return Eigen::Vector3d(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(Scatter(p, c)).eigenvectors().col(2));
  };
  const Eigen::Vector3d us = axis(src, cs);
  Eigen::Vector3d ud = axis(dst, cd);
  double sxy = 0, sxx = 0;
  for (size_t i = 0; i < n; ++i) {
    const double a = (src[i] - cs).dot(us), b = (dst[i] - cd).dot(ud);
    sxy += a * b, sxx += a * a;
  }
  if (!(sxx > 0) || sxy == 0) return false;
  if (sxy < 0) ud = -ud, sxy = -sxy;
  sim->s = sxy / sxx;
  sim->q = Eigen::Quaterniond::FromTwoVectors(us, ud);
  sim->t = cd - sim->s * (sim->q * cs);
  return true;
}

double Collinearity(const std::vector<Eigen::Vector3d>& p) {
  if (p.empty()) return 0;
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(Scatter(p, Centroid(p))).eigenvalues();
  return ev(2) > 0 ? std::sqrt(std::max(0.0, ev(1)) / ev(2)) : 0;
}

bool EstimateScaleShift(const Eigen::Matrix3d& R, const std::vector<Eigen::Vector3d>& src,
                        const std::vector<Eigen::Vector3d>& dst, const std::vector<double>& weights, ScaleShift* out) {
  if (dst.size() != src.size() || weights.size() != src.size()) return false;
  Eigen::Matrix4d A = Eigen::Matrix4d::Zero();
  Eigen::Vector4d b = Eigen::Vector4d::Zero();
  for (size_t i = 0; i < src.size(); ++i) {
    Eigen::Matrix<double, 3, 4> J;
    J.col(0) = R * src[i];
    J.rightCols<3>().setIdentity();
    A += weights[i] * J.transpose() * J;
    b += weights[i] * J.transpose() * dst[i];
  }
  const Eigen::FullPivLU<Eigen::Matrix4d> lu(A);
  if (lu.rank() < 4) return false;
  const Eigen::Vector4d x = lu.solve(b);
  if (!x.allFinite() || !(x(0) > 0)) return false;
  out->scale = x(0);
  out->translation = x.tail<3>();
  out->covariance = lu.inverse();
  return true;
}

void SimilarityRansacOptions::Check() const {
  if (!(max_error > 0)) throw Error("similarity RANSAC: max_error must be > 0");
  if (max_iterations < 1) throw Error("similarity RANSAC: max_iterations must be ≥ 1");
}

int EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                             const SimilarityRansacOptions& options, core::Sim3* sim, std::vector<char>* inlier_mask) {
  options.Check();
  const size_t n = src.size();
  if (n < 3 || dst.size() != n) return 0;
  RobustOptions ro;
  ro.score = RobustOptions::Score::kRansac;
  ro.max_residual = options.max_error;
  ro.max_iterations = options.max_iterations;
  ro.seed = options.seed;
  const SimilarityProblem problem{src, dst};
  const auto found = EstimateRobust(problem, ro);
  if (!found.found || found.num_inliers < 3) return 0;
  core::Sim3 best = found.model;
  const auto count = [&](const core::Sim3& s, std::vector<char>* mask) {
    size_t c = 0;
    if (mask) mask->assign(n, 0);
    for (size_t i = 0; i < n; ++i) {
      const bool in = problem.Residual(s, i) <= options.max_error;
      c += in;
      if (mask) (*mask)[i] = in;
    }
    return c;
  };
  // Least squares on the inliers, then re-count (twice, so the final inlier set matches the final model).
  std::vector<char> mask;
  for (int round = 0; round < 2; ++round) {
    count(best, &mask);
    std::vector<Eigen::Vector3d> a, b;
    for (size_t i = 0; i < n; ++i)
      if (mask[i]) a.push_back(src[i]), b.push_back(dst[i]);
    core::Sim3 refined;
    if (EstimateSimilarity(a, b, &refined) && count(refined, nullptr) >= a.size()) best = refined;
  }
  *sim = best;
  const size_t c = count(best, &mask);
  if (inlier_mask) *inlier_mask = mask;
  return static_cast<int>(c);
}

void SimilarityLMedSOptions::Check() const {
  if (max_samples < 1) throw Error("similarity LMedS: max_samples must be positive");
  if (!(min_inlier_threshold > 0)) throw Error("similarity LMedS: min_inlier_threshold must be positive");
}

SimilarityLMedS EstimateSimilarityLMedS(const std::vector<Eigen::Vector3d>& src,
                                        const std::vector<Eigen::Vector3d>& dst, const SimilarityLMedSOptions& o) {
  o.Check();
  const size_t n = src.size();
  if (n < 3 || dst.size() != n) throw Error(fmt::format("similarity: {} point pairs, at least 3 needed", n));
  RobustOptions ro;
  ro.score = RobustOptions::Score::kLMedS;
  ro.max_iterations = o.max_samples;
  ro.exhaustive_up_to = 14;
  ro.seed = o.seed;
  SimilarityLMedS out;
  out.along_line = Collinearity(src) < 1e-3;
  auto best = EstimateRobust(SimilarityProblem{src, dst, false}, ro);
  if (!best.found && out.along_line) best = EstimateRobust(SimilarityProblem{src, dst, true}, ro);
  if (!best.found) throw Error("similarity: no sample gives a similarity (degenerate point positions)");
  const auto fit = [&](const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b, core::Sim3* s) {
    return out.along_line ? EstimateSimilarityAlongLine(a, b, s) : EstimateSimilarity(a, b, s);
  };
  double sigma = (1 + 5.0 / std::max<double>(1, static_cast<double>(n) - 3)) * best.score / 1.538;
  out.inliers.assign(n, 1);
  out.sim = best.model;
  for (int round = 0; round < 3; ++round) {
    const double bound = std::max(o.min_inlier_threshold, 3.5 * sigma);
    std::vector<Eigen::Vector3d> s_in, d_in;
    for (size_t i = 0; i < n; ++i) {
      out.inliers[i] = (out.sim.Apply(src[i]) - dst[i]).norm() <= bound;
      if (out.inliers[i]) s_in.push_back(src[i]), d_in.push_back(dst[i]);
    }
    core::Sim3 refit;
    if (s_in.size() < 3 || !fit(s_in, d_in, &refit)) break;
    out.sim = refit;
    double sq = 0;
    for (size_t i = 0; i < n; ++i)
      if (out.inliers[i]) sq += (out.sim.Apply(src[i]) - dst[i]).squaredNorm();
    sigma = std::sqrt(sq / (3.0 * std::max<double>(1, static_cast<double>(s_in.size()) - 7.0 / 3)));
  }
  out.sigma = sigma;
  return out;
}

}  // namespace fmv3d::geometry
