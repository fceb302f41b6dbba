#include "fmv3d/geo/frame_centres.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "fmv3d/core/stats.h"

namespace fmv3d::geo {

namespace {

Eigen::Vector4d Params(const ScaleShift& s) {
  Eigen::Vector4d x;
  x << s.scale, s.translation;
  return x;
}

// Residual of one point: exp(ls)·rot(ω)·u + t + range·rot(ω)·v − target, over σ. u, v already rotated by the
// starting rotation; a position is the case v = 0.
struct PointResidual {
  Eigen::Vector3d u, v, target;
  double range, sigma;
  template <typename T>
  bool operator()(const T* w, const T* ls, const T* t, T* r) const {
    const T u_[3] = {T(u.x()), T(u.y()), T(u.z())}, v_[3] = {T(v.x()), T(v.y()), T(v.z())};
    T ru[3], rv[3];
    ceres::AngleAxisRotatePoint(w, u_, ru);
    ceres::AngleAxisRotatePoint(w, v_, rv);
    const T s = exp(ls[0]);
    for (int k = 0; k < 3; ++k) r[k] = (s * ru[k] + t[k] + T(range) * rv[k] - T(target(k))) / T(sigma);
    return true;
  }
};

// An attitude's rotation relative to the start, e = log(A·R0ᵀ), against the increment ω (small angles).
struct RotationResidual {
  Eigen::Vector3d e;
  double sigma;
  template <typename T>
  bool operator()(const T* w, T* r) const {
    for (int k = 0; k < 3; ++k) r[k] = (w[k] - T(e(k))) / T(sigma);
    return true;
  }
};

}  // namespace

core::Sim3 RefineSimilarity(const core::Sim3& start, const JointMeasurements& m) {
  const Eigen::Matrix3d R0 = start.q.toRotationMatrix();
  double w[3] = {0, 0, 0}, ls[1] = {std::log(start.s)}, t[3] = {start.t.x(), start.t.y(), start.t.z()};
  ceres::Problem problem;
  for (size_t i = 0; i < m.src.size(); ++i)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PointResidual, 3, 3, 1, 3>(new PointResidual{
                                 R0 * m.src[i], Eigen::Vector3d::Zero(), m.dst[i], 0.0, m.position_sigma}),
                             nullptr, w, ls, t);
  for (const auto& l : m.sights)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PointResidual, 3, 3, 1, 3>(new PointResidual{
                                 R0 * l.model_centre, R0 * l.model_axis, l.frame_centre, l.slant_range, m.sight_sigma}),
                             nullptr, w, ls, t);
  for (const auto& a : m.attitudes) {
    const Eigen::AngleAxisd d(a * R0.transpose());
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<RotationResidual, 3, 3>(
                                 new RotationResidual{d.angle() * d.axis(), m.attitude_sigma_rad}),
                             nullptr, w);
  }
  problem.AddResidualBlock(new ceres::AutoDiffCostFunction<RotationResidual, 3, 3>(
                               new RotationResidual{Eigen::Vector3d::Zero(), 5 * M_PI / 180}),
                           nullptr, w);
  ceres::Solver::Options options;
  options.max_num_iterations = 50;
  options.linear_solver_type = ceres::DENSE_QR;
  options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  core::Sim3 out = start;
  if (!summary.IsSolutionUsable()) return out;
  const Eigen::Vector3d wv(w[0], w[1], w[2]);
  const Eigen::Matrix3d dR =
      wv.norm() > 0 ? Eigen::AngleAxisd(wv.norm(), wv.normalized()).toRotationMatrix() : Eigen::Matrix3d::Identity();
  out.q = Eigen::Quaterniond(dR * R0).normalized();
  out.s = std::exp(ls[0]);
  out.t = Eigen::Vector3d(t[0], t[1], t[2]);
  return out;
}

SightScatter OwnScatter(const core::Sim3& start, const std::vector<LineOfSight>& sights, double sigma_start) {
  SightScatter out;
  const size_t n = sights.size();
  if (n < 3) return out;
  JointMeasurements m;
  m.sights = sights;
  m.sight_sigma = std::max(sigma_start, 1e-3);
  const core::Sim3 own = RefineSimilarity(start, m);
  const Eigen::Matrix3d R = own.q.toRotationMatrix();
  double sq = 0, num = 0;
  std::vector<Eigen::Vector3d> r(n);
  for (size_t i = 0; i < n; ++i) {
    r[i] = own.s * (R * sights[i].model_centre) + own.t + sights[i].slant_range * (R * sights[i].model_axis) -
           sights[i].frame_centre;
    sq += r[i].squaredNorm();
    if (i > 0 && sights[i].track == sights[i - 1].track) num += r[i].dot(r[i - 1]);
  }
  out.sigma = std::max(1e-3, std::sqrt(sq / std::max(1.0, 3.0 * n - 7)));  // 7 parameters fitted
  out.autocorrelation = sq > 0 ? std::clamp(num / sq, 0.0, 0.999) : 0.0;
  out.effective_samples = std::max(1.0, n * (1 - out.autocorrelation) / (1 + out.autocorrelation));
  out.sigma_effective = out.sigma * std::sqrt(n / out.effective_samples);
  return out;
}

FrameCentreFusion FuseFrameCentres(const Eigen::Matrix3d& R, const ScaleShift& positions,
                                   const std::vector<LineOfSight>& sights, double min_threshold,
                                   const Eigen::Vector3d& systematic,
                                   const std::vector<std::pair<double, double>>& vertical_offset_prior) {
  FrameCentreFusion f;
  f.observations = sights.size();
  if (sights.size() < 3) {
    f.outcome = FrameCentreFusion::Outcome::kTooFew;
    return f;
  }
  // The sensor position each line of sight implies: F − r·(R·a).
  const size_t n = sights.size();
  std::vector<Eigen::Vector3d> src(n), dst(n);
  for (size_t i = 0; i < n; ++i) {
    src[i] = sights[i].model_centre;
    dst[i] = sights[i].frame_centre - sights[i].slant_range * (R * sights[i].model_axis);
  }
  // Robust σ from the median residual (as the positions' fit), inliers within 3.5 σ, refit, three rounds.
  std::vector<char> in(n, 1);
  ScaleShift fit;
  double sigma = 0;
  for (int round = 0; round < 4; ++round) {
    std::vector<Eigen::Vector3d> s_in, d_in;
    for (size_t i = 0; i < n; ++i)
      if (in[i]) s_in.push_back(src[i]), d_in.push_back(dst[i]);
    if (s_in.size() < 3 || !geometry::EstimateScaleShift(R, s_in, d_in, std::vector<double>(s_in.size(), 1.0), &fit)) {
      f.outcome = FrameCentreFusion::Outcome::kUndetermined;
      return f;
    }
    std::vector<double> res(n), res_in;
    for (size_t i = 0; i < n; ++i) {
      res[i] = (fit.scale * (R * src[i]) + fit.translation - dst[i]).norm();
      if (in[i]) res_in.push_back(res[i]);
    }
    if (round == 0) {
      sigma = (1 + 5.0 / std::max<double>(1, res_in.size() - 3.0)) * core::Median(res_in) / 1.538;
    } else {
      double sq = 0;
      for (double r : res_in) sq += r * r;
      sigma = std::sqrt(sq / (3.0 * std::max(1.0, res_in.size() - 4.0 / 3)));
    }
    const double bound = std::max(min_threshold, 3.5 * sigma);
    for (size_t i = 0; i < n; ++i) in[i] = res[i] <= bound;
  }
  sigma = std::max(sigma, 1e-3);  // quantisation of the encoded fields; no measurement is exact
  // Errors that persist along the track (a frame centre computed from a smooth GPS) count as fewer samples.
  std::vector<Eigen::Vector3d> r(n);
  for (size_t i = 0; i < n; ++i) r[i] = fit.scale * (R * src[i]) + fit.translation - dst[i];
  double num = 0, den = 0;
  size_t n_in = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!in[i]) continue;
    ++n_in;
    den += r[i].squaredNorm();
    if (i + 1 < n && in[i + 1] && sights[i + 1].track == sights[i].track) num += r[i].dot(r[i + 1]);
  }
  f.inliers = n_in;
  f.inlier_mask = in;
  f.sigma_m = sigma;
  f.autocorrelation = den > 0 ? std::clamp(num / den, 0.0, 0.999) : 0.0;
  f.effective_samples = std::max(1.0, n_in * (1 - f.autocorrelation) / (1 + f.autocorrelation));
  if (n_in < 3) {
    f.outcome = FrameCentreFusion::Outcome::kInconsistent;
    return f;
  }
  // Covariance of the line-of-sight fit: σ² per axis, discounted to the effective samples.
  ScaleShift los = fit;
  los.covariance *= sigma * sigma * static_cast<double>(n_in) / f.effective_samples;
  los.covariance.bottomRightCorner<3, 3>() += systematic.cwiseAbs2().asDiagonal();
  // The common height offset u of the frame centres over its prior's nodes, each a Gaussian fusion of the
  // positions with the frame centres shifted by u, weighted by its prior and by how well the two then agree. One
  // node (u = 0) when there is no such offset. The mixture's mean and covariance are the answer.
  const std::vector<std::pair<double, double>> prior =
      vertical_offset_prior.empty() ? std::vector<std::pair<double, double>>{{0.0, 1.0}} : vertical_offset_prior;
  const int nodes = static_cast<int>(prior.size());
  const Eigen::Matrix4d c = los.covariance + positions.covariance;
  const Eigen::FullPivLU<Eigen::Matrix4d> c_lu(c);
  const Eigen::Matrix4d info_p = positions.covariance.inverse(), info_l = los.covariance.inverse();
  const Eigen::Matrix4d cov = (info_p + info_l).inverse();
  std::vector<double> chi2(nodes);
  std::vector<Eigen::Vector4d> x(nodes);
  f.chi2 = std::numeric_limits<double>::infinity();
  for (int k = 0; k < nodes; ++k) {
    Eigen::Vector4d l = Params(los);
    l(3) += prior[k].first;
    const Eigen::Vector4d d = l - Params(positions);
    chi2[k] = d.dot(c_lu.solve(d));
    x[k] = cov * (info_p * Params(positions) + info_l * l);
    if (std::isfinite(chi2[k]) && prior[k].second > 0) f.chi2 = std::min(f.chi2, chi2[k]);
  }
  if (!std::isfinite(f.chi2) || f.chi2 > kFrameCentreAgreementChi2) {  // at the offset that agrees best
    f.outcome = FrameCentreFusion::Outcome::kDisagree;
    return f;
  }
  double wsum = 0;
  Eigen::Vector4d mean = Eigen::Vector4d::Zero();
  std::vector<double> weight(nodes);
  for (int k = 0; k < nodes; ++k) {
    weight[k] = std::isfinite(chi2[k]) ? prior[k].second * std::exp(-0.5 * (chi2[k] - f.chi2)) : 0.0;
    wsum += weight[k];
    mean += weight[k] * x[k];
  }
  if (!(wsum > 0)) {
    f.outcome = FrameCentreFusion::Outcome::kDisagree;
    return f;
  }
  mean /= wsum;
  Eigen::Matrix4d spread = Eigen::Matrix4d::Zero();
  for (int k = 0; k < nodes; ++k) spread += weight[k] / wsum * (x[k] - mean) * (x[k] - mean).transpose();
  if (!mean.allFinite() || !(mean(0) > 0)) {
    f.outcome = FrameCentreFusion::Outcome::kNonPositiveScale;
    return f;
  }
  f.used = true;
  f.outcome = FrameCentreFusion::Outcome::kUsed;
  f.fused.scale = mean(0);
  f.fused.translation = mean.tail<3>();
  f.fused.covariance = cov + spread;
  return f;
}

std::string FrameCentreFusion::Why() const {
  switch (outcome) {
    case Outcome::kUsed:
      return "";
    case Outcome::kTooFew:
      return "fewer than 3 packets state a frame centre and a slant range";
    case Outcome::kUndetermined:
      return "the lines of sight do not determine a scale and translation";
    case Outcome::kInconsistent:
      return "fewer than 3 lines of sight agree with each other";
    case Outcome::kDisagree:
      return "the frame centres disagree with the positions beyond their uncertainties";
    case Outcome::kNonPositiveScale:
      return "the fused scale is not positive";
  }
  return "";
}

nlohmann::json FrameCentreFusion::ToJson() const {
  nlohmann::json j = {{"used", used},
                      {"observations", observations},
                      {"inliers", inliers},
                      {"sigma_per_axis_m", sigma_m},
                      {"residual_autocorrelation", autocorrelation},
                      {"effective_samples", effective_samples},
                      {"chi2_vs_positions", chi2}};
  if (!used) j["why"] = Why();
  if (used)
    j["expected_translation_error_m"] = std::sqrt(std::max(0.0, fused.covariance.bottomRightCorner<3, 3>().trace()));
  return j;
}

}  // namespace fmv3d::geo
