#include "fmv3d/geo/roll_levelling.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <tuple>
#include <utility>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/robust.h"

namespace fmv3d::geo {
namespace {

// Smallest principal axis and centroid.
std::pair<Eigen::Vector3d, Eigen::Vector3d> PlaneFit(const std::vector<Eigen::Vector3d>& v) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : v) mean += p;
  mean /= static_cast<double>(v.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : v) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  return {Eigen::Vector3d(eig.eigenvectors().col(0)), mean};
}

struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(), point = Eigen::Vector3d::Zero();
};

struct PlaneProblem {
  using Model = Plane;
  static constexpr int kSampleSize = 3;
  const std::vector<Eigen::Vector3d>& pts;
  size_t NumData() const { return pts.size(); }
  bool Fit(const std::vector<size_t>& s, Model* m) const {
    const Eigen::Vector3d n = (pts[s[1]] - pts[s[0]]).cross(pts[s[2]] - pts[s[0]]);
    if (n.norm() < 1e-12) return false;
    m->normal = n.normalized();
    m->point = pts[s[0]];
    return true;
  }
  double Residual(const Model& m, size_t i) const { return std::abs(m.normal.dot(pts[i] - m.point)); }
};

}  // namespace

const char* RollSourceName(RollSource s) {
  return s == RollSource::kCameraPositions ? "camera positions"
                                           : "ground plane of the sparse points (nearly straight track)";
}

std::optional<Eigen::Vector3d> GroundNormal(const std::vector<Eigen::Vector3d>& pts, const Eigen::Vector3d& above) {
  if (pts.size() < 10) return std::nullopt;
  auto [normal, centre] = PlaneFit(pts);
  std::vector<double> dist(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) dist[i] = (pts[i] - centre).norm();
  geometry::RobustOptions o;
  o.max_residual = 0.01 * core::Median(dist);
  o.max_iterations = 500;
  o.stop_when_all_inliers = false;
  o.seed = 7;
  const auto best = o.max_residual > 0 ? geometry::EstimateRobust(PlaneProblem{pts}, o)
                                       : geometry::RobustResult<Plane>{};  // every point at one place
  if (best.found) {
    std::vector<Eigen::Vector3d> inliers;
    for (size_t i = 0; i < pts.size(); ++i)
      if (best.inliers[i]) inliers.push_back(pts[i]);
    normal = best.model.normal, centre = best.model.point;
    if (inliers.size() >= 10) std::tie(normal, centre) = PlaneFit(inliers);
  }
  if (normal.dot(above - centre) < 0) normal = -normal;
  return normal;
}

core::Sim3 LevelAboutAxis(const core::Sim3& sim, const Eigen::Vector3d& axis, const Eigen::Vector3d& centre,
                          const Eigen::Vector3d& model_normal) {
  const Eigen::Vector3d d = axis.normalized();
  const Eigen::Vector3d v = sim.q * model_normal, z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d vp = v - v.dot(d) * d, zp = z - z.dot(d) * d;
  if (vp.norm() < 1e-9 || zp.norm() < 1e-9) return sim;
  const double angle = std::atan2(vp.cross(zp).dot(d), vp.dot(zp));
  const Eigen::Quaterniond fix(Eigen::AngleAxisd(angle, d));
  core::Sim3 out;
  out.s = sim.s;
  out.q = (fix * sim.q).normalized();
  out.t = fix * (sim.t - centre) + centre;  // X' = fix (sim(X) - c) + c
  return out;
}

RollLevelling LevelRollFromGround(const core::Sim3& sim, const std::vector<Eigen::Vector3d>& src,
                                  const std::vector<Eigen::Vector3d>& dst, double sigma,
                                  const std::vector<Eigen::Vector3d>& model_points) {
  RollLevelling out{sim, RollSource::kCameraPositions};
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : dst) mean += p;
  mean /= static_cast<double>(dst.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : dst) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const double lateral_sd = std::sqrt(std::max(0.0, eig.eigenvalues()(1)) / dst.size());
  const double along_sd = std::sqrt(std::max(0.0, eig.eigenvalues()(2)) / dst.size());
  if (lateral_sd >= std::max(sigma, 0.05 * along_sd)) return out;  // sideways spread beyond the noise
  Eigen::Vector3d model_above = Eigen::Vector3d::Zero();
  for (const auto& c : src) model_above += c;
  const auto normal = GroundNormal(model_points, model_above / static_cast<double>(src.size()));
  if (!normal)
    throw Error(
        "georef: the camera positions lie nearly on a line and the model has too few points to find "
        "the ground: the rotation about the track is unknown (fly a curve or an orbit)");
  out.sim = LevelAboutAxis(sim, eig.eigenvectors().col(2), mean, *normal);
  out.source = RollSource::kGroundPlane;
  return out;
}

}  // namespace fmv3d::geo
