#include "fmv3d/geo/attitude_fusion.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>

#include "fmv3d/geometry/similarity.h"

namespace fmv3d::geo {

Eigen::Vector3d LogRotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

double AttitudeFusion::EffectiveSigma() const {
  return effective_samples > 0 ? sigma_rad * std::sqrt(rotations.size() / effective_samples) : 1.0;
}

nlohmann::json AttitudeFusion::ToJson() const {
  if (!evaluated) return {{"used", false}};
  nlohmann::json j = {{"used", used},
                      {"frames", frames},
                      {"residual_autocorrelation", autocorrelation},
                      {"effective_samples", effective_samples},
                      {"scatter_deg", sigma_rad * 180 / M_PI},
                      {"disagreement_deg", disagreement_rad * 180 / M_PI},
                      {"chi2", chi2}};
  if (used) j["correction_deg"] = correction_rad * 180 / M_PI;
  return j;
}

namespace {

// Chordal mean of rotations: the nearest rotation to their sum.
Eigen::Matrix3d ChordalMean(const std::vector<Eigen::Matrix3d>& rel) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& r : rel) sum += r;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0) d(2, 2) = -1;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

// Information about a small world-frame rotation of the positions about their inlier centroid.
Eigen::Matrix3d PositionRotationInformation(const core::Sim3& sim, const std::vector<Eigen::Vector3d>& src,
                                            const std::vector<Eigen::Vector3d>& dst, const std::vector<char>& inliers,
                                            double sigma) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  size_t n_in = 0;
  for (size_t i = 0; i < dst.size(); ++i)
    if (inliers[i]) mean += dst[i], ++n_in;
  mean /= static_cast<double>(n_in);
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < dst.size(); ++i) {
    if (!inliers[i]) continue;
    const Eigen::Vector3d d = sim.Apply(src[i]) - mean;
    Eigen::Matrix3d dx;
    dx << 0, -d.z(), d.y(), d.z(), 0, -d.x(), -d.y(), d.x(), 0;
    info += dx.transpose() * dx / (sigma * sigma);
  }
  return info;
}

}  // namespace

AttitudeFusion FuseAttitude(const core::Sim3& sim, const std::vector<GeorefPair>& pairs,
                            const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                            const std::vector<char>& inliers, double sigma) {
  AttitudeFusion f;
  f.sim = sim;
  std::vector<Eigen::Matrix3d> rel;  // camera-to-ENU · model-to-camera = model-to-ENU
  std::vector<size_t> rel_pair;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!inliers[i] || !pairs[i].attitude) continue;
    rel.push_back(*pairs[i].attitude * pairs[i].rotation.toRotationMatrix());
    rel_pair.push_back(i);
  }
  if (rel.size() < 3) return f;
  f.evaluated = true;
  f.frames = rel.size();
  const Eigen::Matrix3d r_att = ChordalMean(rel);
  double sq = 0;
  std::vector<Eigen::Vector3d> att_res(pairs.size(), Eigen::Vector3d::Zero());
  std::vector<char> att_in(pairs.size(), 0);
  for (size_t k = 0; k < rel.size(); ++k) {
    att_res[rel_pair[k]] = LogRotation(rel[k] * r_att.transpose());
    att_in[rel_pair[k]] = 1;
    sq += att_res[rel_pair[k]].squaredNorm();
  }
  f.sigma_rad = std::max(1e-4, std::sqrt(sq / (3.0 * rel.size())));
  // Between keyframes the model's rotation is interpolated and misses the camera's jitter, an error shared by
  // neighbouring packets: they count as fewer samples.
  f.autocorrelation = ResidualAutocorrelation(pairs, att_res, att_in);
  f.effective_samples = std::max(1.0, rel.size() * (1 - f.autocorrelation) / (1 + f.autocorrelation));
  const Eigen::Matrix3d r_pos = sim.q.toRotationMatrix();
  const Eigen::Vector3d w_att = LogRotation(r_att * r_pos.transpose());  // world-frame correction
  const Eigen::Matrix3d info_pos = PositionRotationInformation(sim, src, dst, inliers, sigma);
  const Eigen::Matrix3d info_att = Eigen::Matrix3d::Identity() * (rel.size() / (f.sigma_rad * f.sigma_rad));
  const Eigen::Matrix3d cov_diff = info_pos.inverse() + info_att.inverse();
  f.chi2 = w_att.dot(cov_diff.inverse() * w_att);
  f.disagreement_rad = w_att.norm();
  if (!(f.chi2 < 16.3 && info_pos.allFinite())) {  // 99.9% of a 3-dof χ²
    spdlog::warn("georef: telemetry attitude disagrees with the positions ({:.2f}°, χ² {:.1f}); not used",
                 w_att.norm() * 180 / M_PI, f.chi2);
    return f;
  }
  const Eigen::Vector3d w = (info_pos + info_att).inverse() * info_att * w_att;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(w.norm(), w.norm() > 0 ? w.normalized() : Eigen::Vector3d::UnitZ()).toRotationMatrix() * r_pos;
  std::vector<Eigen::Vector3d> s_in, d_in;
  for (size_t i = 0; i < src.size(); ++i)
    if (inliers[i]) s_in.push_back(src[i]), d_in.push_back(dst[i]);
  geometry::ScaleShift ss;  // scale and translation for this rotation (least squares on the inliers)
  if (!geometry::EstimateScaleShift(R, s_in, d_in, std::vector<double>(s_in.size(), 1.0), &ss)) return f;
  f.sim.q = Eigen::Quaterniond(R).normalized();
  f.sim.s = ss.scale;
  f.sim.t = ss.translation;
  f.used = true;
  f.correction_rad = w.norm();
  f.rotations = rel;
  return f;
}

}  // namespace fmv3d::geo
