// Bundle adjustment's prior cost functions (bundle_adjustment.h), Ceres-style: one small functor per prior, each
// residual already divided by its σ. Poses are world-to-camera (q, t) with q in Eigen's x y z w order; the
// reprojection error itself is geometry/reprojection_error.h's. Included by bundle_adjustment.cc only.
#pragma once

#include <ceres/sized_cost_function.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "fmv3d/core/camera.h"

namespace fmv3d::sfm::ba {

// w · (t[k] − t0): holds one translation coordinate (the gauge of scale), weighted relative to its size.
class ScaleGaugePrior : public ceres::SizedCostFunction<1, 3> {
 public:
  ScaleGaugePrior(int k, double t0) : k_(k), t0_(t0), w_(1e3 / std::max(std::abs(t0), 1e-9)) {}
  bool Evaluate(double const* const* params, double* residual, double** jacobians) const override {
    residual[0] = w_ * (params[0][k_] - t0_);
    if (jacobians && jacobians[0]) {
      jacobians[0][0] = jacobians[0][1] = jacobians[0][2] = 0;
      jacobians[0][k_] = w_;
    }
    return true;
  }

 private:
  int k_;
  double t0_, w_;
};

// (C − prior) / σ with C = −Rᵀt, the camera centre of pose (q, t) (q in Eigen's x y z w order).
struct CentrePrior {
  CentrePrior(const Eigen::Vector3d& prior, double sigma) : prior_(prior), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, const T* t, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> c = -(rot.conjugate() * Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]));
    for (int k = 0; k < 3; ++k) residual[k] = (c[k] - T(prior_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d prior_;
  double inv_sigma_;
};

// (Rᵀ·z − axis) / σ: the optical axis of pose q (world-to-camera, Eigen x y z w order) in the world frame.
struct AxisPrior {
  AxisPrior(const Eigen::Vector3d& axis, double sigma) : axis_(axis.normalized()), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> z = rot.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    for (int k = 0; k < 3; ++k) residual[k] = (z[k] - T(axis_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d axis_;
  double inv_sigma_;
};

// (C + r·Rᵀ·z − F) / σ: the point at range r along the optical axis of pose (q, t), against a frame centre F.
struct SightPrior {
  SightPrior(const Eigen::Vector3d& frame_centre, double range, double sigma)
      : f_(frame_centre), range_(range), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* q, const T* t, T* residual) const {
    const Eigen::Quaternion<T> rot(q[3], q[0], q[1], q[2]);
    const Eigen::Matrix<T, 3, 1> c = -(rot.conjugate() * Eigen::Matrix<T, 3, 1>(t[0], t[1], t[2]));
    const Eigen::Matrix<T, 3, 1> z = rot.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    for (int k = 0; k < 3; ++k) residual[k] = (c[k] + T(range_) * z[k] - T(f_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d f_;
  double range_, inv_sigma_;
};

// (f − prior) / σ: a camera's focal (intrinsics block in core::IntrinsicIndex order) against a stated one.
class FocalPrior : public ceres::SizedCostFunction<1, core::kNumIntrinsics> {
 public:
  FocalPrior(double prior, double sigma) : prior_(prior), inv_sigma_(1 / sigma) {}
  bool Evaluate(double const* const* params, double* residual, double** jacobians) const override {
    residual[0] = (params[0][core::kF] - prior_) * inv_sigma_;
    if (jacobians && jacobians[0]) {
      std::fill(jacobians[0], jacobians[0] + core::kNumIntrinsics, 0.0);
      jacobians[0][core::kF] = inv_sigma_;
    }
    return true;
  }

 private:
  double prior_, inv_sigma_;
};

// (X − prior) / σ: a 3D point against its known position.
struct PointPrior {
  PointPrior(const Eigen::Vector3d& prior, double sigma) : prior_(prior), inv_sigma_(1 / sigma) {}
  template <typename T>
  bool operator()(const T* X, T* residual) const {
    for (int k = 0; k < 3; ++k) residual[k] = (X[k] - T(prior_[k])) * T(inv_sigma_);
    return true;
  }

 private:
  Eigen::Vector3d prior_;
  double inv_sigma_;
};

}  // namespace fmv3d::sfm::ba
