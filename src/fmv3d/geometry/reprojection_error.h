// The reprojection residual shared by absolute-pose refinement and bundle adjustment: a tiny templated Ceres
// functor around core::ProjectPoint, so every solver uses exactly the camera model that the files describe.
//
// Parameter blocks: intrinsics (core::kNumIntrinsics, layout of core::IntrinsicIndex), world-to-camera rotation as
// an Eigen quaternion (x, y, z, w — use ceres::EigenQuaternionManifold), translation (3), point (3).
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>

#include "fmv3d/core/camera.h"

namespace fmv3d::geometry {

struct ReprojectionError {
  ReprojectionError(double u, double v) : u_(u), v_(v) {}

  template <typename T>
  bool operator()(const T* intr, const T* q, const T* t, const T* X, T* residual) const {
    // Eigen storage (x, y, z, w) → Ceres' (w, x, y, z) for the rotation helper.
    const T q_wxyz[4] = {q[3], q[0], q[1], q[2]};
    T p[3];
    ceres::UnitQuaternionRotatePoint(q_wxyz, X, p);
    p[0] += t[0];
    p[1] += t[1];
    p[2] += t[2];
    T uv[2];
    if (!core::ProjectPoint(intr, p, uv)) {
      // Behind the camera: a large but finite residual keeps the solver away without NaNs.
      residual[0] = T(1e3);
      residual[1] = T(1e3);
      return true;
    }
    residual[0] = uv[0] - T(u_);
    residual[1] = uv[1] - T(v_);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector2d& uv) {
    return new ceres::AutoDiffCostFunction<ReprojectionError, 2, core::kNumIntrinsics, 4, 3, 3>(
        new ReprojectionError(uv.x(), uv.y()));
  }

 private:
  double u_, v_;
};

// Same residual with the point held constant (absolute pose refinement: far fewer parameter blocks).
struct PoseOnlyReprojectionError {
  PoseOnlyReprojectionError(const Eigen::Vector2d& uv, const Eigen::Vector3d& X) : uv_(uv), X_(X) {}

  template <typename T>
  bool operator()(const T* intr, const T* q, const T* t, T* residual) const {
    const T X[3] = {T(X_.x()), T(X_.y()), T(X_.z())};
    return ReprojectionError(uv_.x(), uv_.y())(intr, q, t, X, residual);
  }

  static ceres::CostFunction* Create(const Eigen::Vector2d& uv, const Eigen::Vector3d& X) {
    return new ceres::AutoDiffCostFunction<PoseOnlyReprojectionError, 2, core::kNumIntrinsics, 4, 3>(
        new PoseOnlyReprojectionError(uv, X));
  }

 private:
  Eigen::Vector2d uv_;
  Eigen::Vector3d X_;
};

// The same residual with hand-written derivatives (≈3x faster than automatic differentiation with 18-wide jets;
// bundle adjustment spends most of its time here). Checked against ReprojectionError in the tests.
// Rotation derivative for a unit q = (v, w): R X = X + 2w (v × X) + 2 v × (v × X), so
//   ∂/∂w = 2 v × X,   ∂/∂v = −2w [X]× + 2((v·X) I + v Xᵀ − 2 X vᵀ);
// Ceres' EigenQuaternionManifold chains this with its plus-Jacobian.
class AnalyticReprojectionError final : public ceres::SizedCostFunction<2, core::kNumIntrinsics, 4, 3, 3> {
 public:
  explicit AnalyticReprojectionError(const Eigen::Vector2d& uv) : uv_(uv) {}

  // Defined out of line: one compiled copy (the sanitizer build compiles it optimised, CMakeLists.txt).
  bool Evaluate(double const* const* params, double* residual, double** jac) const override;

 private:
  static constexpr int kBlockSizes[4] = {core::kNumIntrinsics, 4, 3, 3};
  Eigen::Vector2d uv_;
};

}  // namespace fmv3d::geometry
