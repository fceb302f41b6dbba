// The data that flows from features/ to sfm/: keypoints + descriptors per image, and verified pairs.
// Files: features/<frame-stem>.feat (one per image) and matches/matches.bin (all verified pairs); both are our
// own binary formats with a magic, a version and counts, checked on read (see feature_io.h).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

namespace fmv3d::features {

struct Keypoint {
  float x = 0, y = 0;     // pixels, fmv3d/COLMAP convention (pixel centres at +0.5; see core/camera.h)
  float scale = 0;        // SIFT scale (keypoint size / 2), pixels
  float orientation = 0;  // radians
};

// Row-major N x 128 descriptors, uint8 as COLMAP stores them (RootSIFT applied before quantisation if chosen).
using Descriptors = Eigen::Matrix<uint8_t, Eigen::Dynamic, 128, Eigen::RowMajor>;

struct FeatureSet {
  std::string image_name;
  int width = 0, height = 0;
  std::vector<Keypoint> keypoints;
  Descriptors descriptors;
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;  // RGB at each keypoint, for coloured sparse points
  // The SIFT contrast threshold the keypoints were detected with (lowered on faint images); 0 when not recorded
  // (feature files of version 1).
  double contrast_threshold = 0;
};

// Which two-view model explains a verified pair best (COLMAP's "configuration" idea, simplified).
enum class PairGeometry : uint8_t {
  kUndefined = 0,
  kCalibrated = 1,        // essential matrix inliers dominate: general motion, intrinsics known well enough
  kUncalibrated = 2,      // fundamental matrix only
  kPlanarOrRotation = 3,  // homography explains (almost) all F inliers: planar scene or pure rotation
};

struct FeatureMatch {
  uint32_t idx1 = 0, idx2 = 0;  // keypoint indices in image 1 and 2
};

struct VerifiedPair {
  uint32_t image_id1 = 0, image_id2 = 0;  // ids as in frames.json order (1-based), image_id1 < image_id2
  std::vector<FeatureMatch> inliers;      // matches consistent with the chosen geometry
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  uint32_t num_putative = 0, num_inliers_F = 0, num_inliers_E = 0, num_inliers_H = 0;
  PairGeometry geometry = PairGeometry::kUndefined;
  // Added by features/ (additive): the relative pose from E with the prior intrinsics, x_cam2 = R * x_cam1 + t
  // (|t| = 1), valid when has_pose; the median triangulation angle (degrees) of the E inliers that pass the
  // cheirality test — a baseline measure for the initial-pair choice. For "guess" priors the pose is only as good
  // as the guessed focal length.
  bool has_pose = false;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double median_triangulation_angle_deg = 0;
};

}  // namespace fmv3d::features
