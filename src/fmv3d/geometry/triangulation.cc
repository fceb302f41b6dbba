#include "fmv3d/geometry/triangulation.h"

#include <Eigen/Dense>
#include <cmath>
#include <limits>

namespace fmv3d::geometry {

bool TriangulateDLT(const std::vector<core::Pose>& poses, const std::vector<Eigen::Vector2d>& normalized,
                    Eigen::Vector3d* point) {
  const size_t n = poses.size();
  if (n < 2 || normalized.size() != n) return false;
  Eigen::MatrixXd A(2 * n, 4);
  for (size_t i = 0; i < n; ++i) {
    Eigen::Matrix<double, 3, 4> P;
    P.leftCols<3>() = poses[i].R();
    P.col(3) = poses[i].t;
    A.row(2 * i) = normalized[i].x() * P.row(2) - P.row(0);
    A.row(2 * i + 1) = normalized[i].y() * P.row(2) - P.row(1);
  }
  // Rows are normalised so that each view weighs the same regardless of its pose scale.
  for (Eigen::Index r = 0; r < A.rows(); ++r) {
    const double nr = A.row(r).norm();
    if (nr > 0) A.row(r) /= nr;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d X = svd.matrixV().col(3);
  if (std::abs(X(3)) < 1e-14 * X.head<3>().norm() || !X.allFinite()) return false;
  *point = X.head<3>() / X(3);
  return point->allFinite();
}

void RefinePoint(const std::vector<core::Pose>& poses, const std::vector<Eigen::Vector2d>& normalized,
                 Eigen::Vector3d* point, int iterations) {
  auto cost = [&](const Eigen::Vector3d& X) {
    double c = 0;
    for (size_t i = 0; i < poses.size(); ++i) {
      const Eigen::Vector3d p = poses[i].Transform(X);
      if (p.z() <= 0) return std::numeric_limits<double>::infinity();
      c += (p.head<2>() / p.z() - normalized[i]).squaredNorm();
    }
    return c;
  };
  double best = cost(*point);
  for (int it = 0; it < iterations; ++it) {
    Eigen::Matrix3d JtJ = Eigen::Matrix3d::Zero();
    Eigen::Vector3d Jtr = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < poses.size(); ++i) {
      const Eigen::Matrix3d R = poses[i].R();
      const Eigen::Vector3d p = R * *point + poses[i].t;
      const double iz = 1.0 / p.z();
      Eigen::Matrix<double, 2, 3> dproj;
      dproj << iz, 0, -p.x() * iz * iz, 0, iz, -p.y() * iz * iz;
      const Eigen::Matrix<double, 2, 3> J = dproj * R;
      const Eigen::Vector2d r = p.head<2>() * iz - normalized[i];
      JtJ += J.transpose() * J;
      Jtr += J.transpose() * r;
    }
    const Eigen::Vector3d delta = JtJ.ldlt().solve(-Jtr);
    if (!delta.allFinite()) return;
    const Eigen::Vector3d candidate = *point + delta;
    const double c = cost(candidate);
    if (!(c < best)) return;
    const bool converged = best - c < 1e-12 * best;
    best = c;
    *point = candidate;
    if (converged) return;
  }
}

double TriangulationAngle(const Eigen::Vector3d& centre1, const Eigen::Vector3d& centre2,
                          const Eigen::Vector3d& point) {
  const Eigen::Vector3d a = (point - centre1), b = (point - centre2);
  const double na = a.norm(), nb = b.norm();
  if (na == 0 || nb == 0) return 0;
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

double MaxTriangulationAngle(const std::vector<Eigen::Vector3d>& centres, const Eigen::Vector3d& point) {
  double best = 0;
  for (size_t i = 0; i < centres.size(); ++i)
    for (size_t j = i + 1; j < centres.size(); ++j)
      best = std::max(best, TriangulationAngle(centres[i], centres[j], point));
  return best;
}

}  // namespace fmv3d::geometry
