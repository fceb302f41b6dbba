#include "fmv3d/geometry/reprojection_error.h"

namespace fmv3d::geometry {

bool AnalyticReprojectionError::Evaluate(double const* const* params, double* residual, double** jac) const {
  const double* in = params[0];
  const Eigen::Map<const Eigen::Vector3d> v(params[1]);
  const double w = params[1][3];
  const Eigen::Map<const Eigen::Vector3d> t(params[2]);
  const Eigen::Map<const Eigen::Vector3d> X(params[3]);
  const Eigen::Vector3d vx = v.cross(X);
  const Eigen::Vector3d p = X + 2 * w * vx + 2 * v.cross(vx) + t;
  if (!(p.z() > 0)) {
    residual[0] = residual[1] = 1e3;
    for (int b = 0; b < 4; ++b)
      if (jac && jac[b]) std::fill_n(jac[b], 2 * kBlockSizes[b], 0.0);
    return true;
  }
  const double iz = 1 / p.z(), x = p.x() * iz, y = p.y() * iz;
  const double f = in[core::kF], a = in[core::kAspect], k1 = in[core::kK1], k2 = in[core::kK2];
  const double p1 = in[core::kP1], p2 = in[core::kP2];
  const double x2 = x * x, y2 = y * y, xy = x * y, r2 = x2 + y2;
  const double rad = 1 + k1 * r2 + k2 * r2 * r2;
  const double xd = x * rad + 2 * p1 * xy + p2 * (r2 + 2 * x2);
  const double yd = y * rad + p1 * (r2 + 2 * y2) + 2 * p2 * xy;
  const double fx = f * a;
  residual[0] = fx * xd + in[core::kU0] - uv_.x();
  residual[1] = f * yd + in[core::kV0] - uv_.y();
  if (!jac) return true;
  if (jac[0]) {
    Eigen::Map<Eigen::Matrix<double, 2, core::kNumIntrinsics, Eigen::RowMajor>> J(jac[0]);
    J.setZero();
    J(0, core::kF) = a * xd;
    J(0, core::kAspect) = f * xd;
    J(0, core::kU0) = 1;
    J(0, core::kK1) = fx * x * r2;
    J(0, core::kK2) = fx * x * r2 * r2;
    J(0, core::kP1) = fx * 2 * xy;
    J(0, core::kP2) = fx * (r2 + 2 * x2);
    J(1, core::kF) = yd;
    J(1, core::kV0) = 1;
    J(1, core::kK1) = f * y * r2;
    J(1, core::kK2) = f * y * r2 * r2;
    J(1, core::kP1) = f * (r2 + 2 * y2);
    J(1, core::kP2) = f * 2 * xy;
  }
  if (!jac[1] && !jac[2] && !jac[3]) return true;
  const double drad = 2 * (k1 + 2 * k2 * r2);  // ∂rad/∂x = drad·x, ∂rad/∂y = drad·y
  Eigen::Matrix2d D;
  D(0, 0) = rad + x * drad * x + 2 * p1 * y + 6 * p2 * x;
  D(0, 1) = x * drad * y + 2 * p1 * x + 2 * p2 * y;
  D(1, 0) = y * drad * x + 2 * p1 * x + 2 * p2 * y;
  D(1, 1) = rad + y * drad * y + 6 * p1 * y + 2 * p2 * x;
  Eigen::Matrix<double, 2, 3> dxy;
  dxy << iz, 0, -x * iz, 0, iz, -y * iz;
  Eigen::Matrix<double, 2, 3> Jp = D * dxy;
  Jp.row(0) *= fx;
  Jp.row(1) *= f;
  if (jac[1]) {
    Eigen::Matrix3d dv;
    Eigen::Matrix3d Xx;
    Xx << 0, -X.z(), X.y(), X.z(), 0, -X.x(), -X.y(), X.x(), 0;
    dv = -2 * w * Xx + 2 * (v.dot(X) * Eigen::Matrix3d::Identity() + v * X.transpose() - 2 * X * v.transpose());
    Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> J(jac[1]);
    J.leftCols<3>() = Jp * dv;
    J.col(3) = Jp * (2 * vx);
  }
  using Map23 = Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>;
  if (jac[2]) {
    Map23 J(jac[2]);
    J = Jp;
  }
  if (jac[3]) {
    const Eigen::Matrix3d R = Eigen::Quaterniond(w, v.x(), v.y(), v.z()).toRotationMatrix();
    Map23 J(jac[3]);
    J = Jp * R;
  }
  return true;
}

}  // namespace fmv3d::geometry
