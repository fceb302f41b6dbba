#include "fmv3d/core/camera.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::core {
namespace {

// d(xd, yd)/d(x, y) of DistortNormalized at normalised point x.
Eigen::Matrix2d DistortionJacobian(const Camera& c, const Eigen::Vector2d& x) {
  const double r2 = x.squaredNorm();
  const double radial = 1 + c.k1 * r2 + c.k2 * r2 * r2;
  const double dradial = 2 * c.k1 + 4 * c.k2 * r2;  // 2 · d(radial)/d(r²)
  Eigen::Matrix2d J;
  J(0, 0) = radial + x.x() * dradial * x.x() + 2 * c.p1 * x.y() + 6 * c.p2 * x.x();
  J(0, 1) = x.x() * dradial * x.y() + 2 * c.p1 * x.x() + 2 * c.p2 * x.y();
  J(1, 0) = x.y() * dradial * x.x() + 2 * c.p1 * x.x() + 2 * c.p2 * x.y();
  J(1, 1) = radial + x.y() * dradial * x.y() + 6 * c.p1 * x.y() + 2 * c.p2 * x.x();
  return J;
}

}  // namespace

Camera Camera::Pinhole(int width, int height, double f) {
  Camera c;
  c.width = width;
  c.height = height;
  c.f = f;
  c.u0 = width * 0.5;
  c.v0 = height * 0.5;
  return c;
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d k;
  k << fx(), 0, u0, 0, fy(), v0, 0, 0, 1;
  return k;
}

std::array<double, kNumIntrinsics> Camera::Params() const { return {f, aspect, u0, v0, k1, k2, p1, p2}; }

void Camera::SetParams(const double* p) {
  f = p[kF];
  aspect = p[kAspect];
  u0 = p[kU0];
  v0 = p[kV0];
  k1 = p[kK1];
  k2 = p[kK2];
  p1 = p[kP1];
  p2 = p[kP2];
}

Eigen::Vector2d Camera::Distort(const Eigen::Vector2d& xn) const {
  const auto p = Params();
  Eigen::Vector2d d;
  DistortNormalized(p.data(), xn.x(), xn.y(), &d.x(), &d.y());
  return d;
}

Eigen::Vector2d Camera::Undistort(const Eigen::Vector2d& xd) const {
  if (!HasDistortion()) return xd;
  // Newton on D(x) - xd = 0 with the analytic 2x2 Jacobian of D; the plain fixed-point iteration used by
  // many tools stalls near the image corners for strong barrel distortion.
  // Damped Newton: a step is taken only if it reduces the residual and stays where the lens map is locally
  // invertible (det J > 0), so it cannot jump past the fold of a strong barrel lens to a spurious root.
  auto jacobian = [&](const Eigen::Vector2d& x) { return DistortionJacobian(*this, x); };
  Eigen::Vector2d x = xd;
  Eigen::Vector2d r = Distort(x) - xd;
  for (int it = 0; it < 100 && r.squaredNorm() > 1e-30; ++it) {
    const Eigen::Matrix2d J = jacobian(x);
    if (std::abs(J.determinant()) < 1e-12) break;
    Eigen::Vector2d step = J.inverse() * r;
    bool improved = false;
    for (int halvings = 0; halvings < 40; ++halvings, step *= 0.5) {
      const Eigen::Vector2d x_new = x - step;
      const Eigen::Vector2d r_new = Distort(x_new) - xd;
      if (r_new.squaredNorm() < r.squaredNorm() && jacobian(x_new).determinant() > 0) {
        x = x_new;
        r = r_new;
        improved = true;
        break;
      }
    }
    if (!improved) break;
  }
  return x;
}

Eigen::Vector2d Camera::Project(const Eigen::Vector3d& x_cam) const {
  const auto p = Params();
  Eigen::Vector2d uv;
  const double z = x_cam.z();
  const double x = x_cam.x() / z, y = x_cam.y() / z;
  double xd, yd;
  DistortNormalized(p.data(), x, y, &xd, &yd);
  uv << fx() * xd + u0, fy() * yd + v0;
  return uv;
}

Eigen::Vector3d Camera::Unproject(const Eigen::Vector2d& uv) const {
  const Eigen::Vector2d xd((uv.x() - u0) / fx(), (uv.y() - v0) / fy());
  const Eigen::Vector2d x = Undistort(xd);
  return Eigen::Vector3d(x.x(), x.y(), 1.0);
}

Eigen::Matrix<double, 2, 3> Camera::ProjectJacobian(const Eigen::Vector3d& X) const {
  const double iz = 1.0 / X.z();
  const double x = X.x() * iz, y = X.y() * iz;
  const Eigen::Matrix2d Jd = DistortionJacobian(*this, Eigen::Vector2d(x, y));
  Eigen::Matrix<double, 2, 3> Jn;  // d(x, y)/d(X)
  Jn << iz, 0, -x * iz, 0, iz, -y * iz;
  Eigen::Matrix2d F = Eigen::Vector2d(fx(), fy()).asDiagonal();
  return F * Jd * Jn;
}

void Camera::Validate() const {
  std::ostringstream why;
  if (width <= 0 || height <= 0)
    why << "image size " << width << "x" << height << " is not positive";
  else if (!(f > 0) || !std::isfinite(f))
    why << "focal length " << f << " px is not positive";
  else if (!(aspect > 0) || !std::isfinite(aspect))
    why << "aspect ratio " << aspect << " is not positive";
  else if (!std::isfinite(u0) || !std::isfinite(v0))
    why << "principal point is not finite";
  else if (!std::isfinite(k1 + k2 + p1 + p2))
    why << "distortion coefficients are not finite";
  if (!why.str().empty()) throw Error("camera " + std::to_string(id) + ": " + why.str());
}

Camera Camera::Resized(int new_width, int new_height) const {
  const double sx = static_cast<double>(new_width) / width, sy = static_cast<double>(new_height) / height;
  Camera c = *this;
  c.width = new_width;
  c.height = new_height;
  c.f = f * sy;
  c.aspect = aspect * sx / sy;
  c.u0 = u0 * sx;
  c.v0 = v0 * sy;
  return c;
}

Camera Camera::FitWithin(int max_side) const {
  const double scale = std::min(1.0, static_cast<double>(max_side) / std::max(width, height));
  return Resized(std::max(1, static_cast<int>(std::lround(width * scale))),
                 std::max(1, static_cast<int>(std::lround(height * scale))));
}

}  // namespace fmv3d::core
