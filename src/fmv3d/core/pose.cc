#include "fmv3d/core/pose.h"

#include <cmath>

namespace fmv3d::core {

Pose Pose::FromRotationAndCentre(const Eigen::Matrix3d& R, const Eigen::Vector3d& centre) {
  return Pose(Eigen::Quaterniond(R), -R * centre);
}

Pose Pose::LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - centre).normalized();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-9) x = z.cross(Eigen::Vector3d::UnitY());  // looking straight along `up`
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // image down
  Eigen::Matrix3d R;                     // rows are the camera axes in world coordinates
  R.row(0) = x;
  R.row(1) = y;
  R.row(2) = z;
  return FromRotationAndCentre(R, centre);
}

Pose Pose::Inverse() const {
  const Eigen::Quaterniond qi = q.conjugate();
  return Pose(qi, -(qi * t));
}

Pose Pose::operator*(const Pose& o) const { return Pose(q * o.q, q * o.t + t); }

Pose Sim3::Apply(const Pose& pose) const {
  // x_cam = R X + t with X = S⁻¹(X') = Rsᵀ (X' − ts) / s; the camera frame keeps metric scale s.
  const Eigen::Quaterniond qn = pose.q * q.conjugate();
  const Eigen::Vector3d tn = s * pose.t - (qn * t);
  return Pose(qn, tn);
}

Sim3 Sim3::Inverse() const {
  Sim3 inv;
  inv.s = 1.0 / s;
  inv.q = q.conjugate();
  inv.t = -(inv.s * (inv.q * t));
  return inv;
}

Eigen::Matrix4d Sim3::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = s * q.toRotationMatrix();
  m.topRightCorner<3, 1>() = t;
  return m;
}

Eigen::Matrix3d RotationFromOmegaPhiKappa(double omega, double phi, double kappa) {
  return (Eigen::AngleAxisd(kappa, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(phi, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(omega, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d OmegaPhiKappaFromRotation(const Eigen::Matrix3d& R) {
  // R = Rz(κ)Ry(φ)Rx(ω):  R20 = −sin φ,  R21 = cos φ sin ω,  R22 = cos φ cos ω,  R10 = sin κ cos φ,  R00 = cos κ cos φ
  const double phi = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  if (std::hypot(R(0, 0), R(1, 0)) < 1e-12) {  // gimbal lock: only ω ± κ is defined
    return Eigen::Vector3d(0.0, phi, std::atan2(-R(0, 1), R(1, 1)));
  }
  return Eigen::Vector3d(std::atan2(R(2, 1), R(2, 2)), phi, std::atan2(R(1, 0), R(0, 0)));
}

double RotationAngle(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) { return a.angularDistance(b); }

}  // namespace fmv3d::core
