// Camera intrinsics: pinhole + Brown–Conrady distortion (k1 k2 radial, p1 p2 tangential) on normalised
// coordinates, identical to OpenCV's 5-coefficient model without k3 and to COLMAP's OPENCV model.
//
//   x = X/Z, y = Y/Z                                  (normalised, camera frame: +z forward, +x right, +y down)
//   r² = x² + y²,  radial = 1 + k1 r² + k2 r⁴
//   xd = x·radial + 2 p1 x y + p2 (r² + 2x²)
//   yd = y·radial + p1 (r² + 2y²) + 2 p2 x y
//   u  = f·s_u·xd + u0,   v = f·yd + v0               (the seed's eq. 7: D_u s_u and D_v folded into f, s_u)
//
// Pixel convention (used everywhere in fmv3d unless a header says otherwise): continuous coordinates with the
// origin at the top-left *corner* of the image, so the centre of pixel (col i, row j) is (i + 0.5, j + 0.5).
// This is COLMAP's convention, so u0, v0 are written to COLMAP files unchanged. OpenCV's functions put pixel
// centres at integers: subtract 0.5 from our coordinates (and from u0, v0) when calling them.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>

namespace fmv3d::core {

// Parameter block layout shared by Camera::Params(), ProjectPoint() and the bundle adjuster.
enum IntrinsicIndex { kF = 0, kAspect, kU0, kV0, kK1, kK2, kP1, kP2, kNumIntrinsics };

// Applies the distortion to normalised coordinates (x, y). Templated so Ceres can differentiate it.
template <typename T>
inline void DistortNormalized(const T* intr, const T& x, const T& y, T* xd, T* yd) {
  const T x2 = x * x, y2 = y * y, xy = x * y, r2 = x2 + y2;
  const T radial = T(1) + intr[kK1] * r2 + intr[kK2] * r2 * r2;
  *xd = x * radial + T(2) * intr[kP1] * xy + intr[kP2] * (r2 + T(2) * x2);
  *yd = y * radial + intr[kP1] * (r2 + T(2) * y2) + T(2) * intr[kP2] * xy;
}

// Projects a point given in the camera frame to pixels. Returns false when it is not in front (Z <= 0).
template <typename T>
inline bool ProjectPoint(const T* intr, const T* x_cam, T* uv) {
  if (!(x_cam[2] > T(0))) return false;
  const T x = x_cam[0] / x_cam[2], y = x_cam[1] / x_cam[2];
  T xd, yd;
  DistortNormalized(intr, x, y, &xd, &yd);
  uv[0] = intr[kF] * intr[kAspect] * xd + intr[kU0];
  uv[1] = intr[kF] * yd + intr[kV0];
  return true;
}

struct Camera {
  uint32_t id = 1;
  int width = 0, height = 0;
  double f = 0;       // focal length in pixels (vertical)
  double aspect = 1;  // s_u: horizontal focal = f * aspect
  double u0 = 0, v0 = 0;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0;

  // A camera with the principal point at the image centre and no distortion.
  static Camera Pinhole(int width, int height, double f);

  double fx() const { return f * aspect; }
  double fy() const { return f; }
  bool HasDistortion() const { return k1 != 0 || k2 != 0 || p1 != 0 || p2 != 0; }
  Eigen::Matrix3d K() const;
  std::array<double, kNumIntrinsics> Params() const;
  void SetParams(const double* params);

  // Normalised ↔ distorted normalised coordinates.
  Eigen::Vector2d Distort(const Eigen::Vector2d& xn) const;
  // Inverse of Distort by Newton iteration; converges to < 1e-12 (normalised) inside the image for any
  // physically sensible distortion. Returns the best estimate if it does not converge.
  Eigen::Vector2d Undistort(const Eigen::Vector2d& xd) const;

  // Camera-frame point → pixel. The point must be in front of the camera (Z > 0).
  Eigen::Vector2d Project(const Eigen::Vector3d& x_cam) const;
  // Pixel → normalised ray (x, y, 1) in the camera frame (distortion removed).
  Eigen::Vector3d Unproject(const Eigen::Vector2d& uv) const;
  // d(pixel)/d(camera-frame point), for Gauss–Newton refinements outside Ceres.
  Eigen::Matrix<double, 2, 3> ProjectJacobian(const Eigen::Vector3d& x_cam) const;

  // The same lens sampled at width x height pixels: the intrinsics scale about the image corner (exact in the
  // corner-origin pixel convention), and s_u absorbs a change of aspect ratio.
  Camera Resized(int width, int height) const;
  // Resized so that the longer side is at most max_side pixels (an image that small already is kept).
  Camera FitWithin(int max_side) const;

  bool InImage(const Eigen::Vector2d& uv, double margin = 0) const {
    return uv.x() >= margin && uv.y() >= margin && uv.x() <= width - margin && uv.y() <= height - margin;
  }
  // Throws fmv3d::Error when the parameters cannot describe a real camera (size, focal, aspect not positive).
  void Validate() const;
};

}  // namespace fmv3d::core
