// Poses and similarities.
//
// A Pose is world-to-camera: x_cam = R * X + t, camera centre C = -Rᵀ t (COLMAP's convention). The rotation
// is stored as a unit quaternion.
//
// Omega-phi-kappa (the seed's Euler angles, radians) use the standard photogrammetric convention
//   R = R_z(κ) · R_y(φ) · R_x(ω)
// with the elementary right-handed rotations R_x(ω) = [1 0 0; 0 cos ω −sin ω; 0 sin ω cos ω] and likewise for
// y and z. This R is the world-to-camera rotation of the Pose. (The seed's printed matrix is garbled; this is
// the convention its text describes: first about x, then the once-rotated y, then the twice-rotated z.)
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace fmv3d::core {

struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Pose() = default;
  Pose(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
      : q(rotation.normalized()), t(translation) {}
  // From a world-to-camera rotation and the camera centre in world coordinates.
  static Pose FromRotationAndCentre(const Eigen::Matrix3d& R, const Eigen::Vector3d& centre);
  // A camera at `centre` looking at `target`, image "up" (−y) as close to `up` as possible.
  static Pose LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target,
                     const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

  Eigen::Matrix3d R() const { return q.toRotationMatrix(); }
  Eigen::Vector3d Centre() const { return -(q.conjugate() * t); }
  Eigen::Vector3d Transform(const Eigen::Vector3d& X) const { return q * X + t; }
  // Viewing direction (+z of the camera) in world coordinates.
  Eigen::Vector3d ViewDirection() const { return q.conjugate() * Eigen::Vector3d::UnitZ(); }
  Pose Inverse() const;
  Pose operator*(const Pose& other) const;  // (this ∘ other)(X) = this(other(X))
};

// Similarity transform X' = s·R·X + t (used to align models to each other or to ground truth).
struct Sim3 {
  double s = 1;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d Apply(const Eigen::Vector3d& X) const { return s * (q * X) + t; }
  // The pose of the same camera after the world was transformed by this similarity.
  Pose Apply(const Pose& pose) const;
  Sim3 Inverse() const;
  Eigen::Matrix4d Matrix() const;
};

Eigen::Matrix3d RotationFromOmegaPhiKappa(double omega, double phi, double kappa);
// Inverse of RotationFromOmegaPhiKappa with φ in [−π/2, π/2]; at gimbal lock (|φ| = π/2) ω is set to 0.
Eigen::Vector3d OmegaPhiKappaFromRotation(const Eigen::Matrix3d& R);

// Angle (radians) of the rotation that takes a to b.
double RotationAngle(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

}  // namespace fmv3d::core
