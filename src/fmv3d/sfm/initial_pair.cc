#include "fmv3d/sfm/initial_pair.h"

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <vector>

#include "fmv3d/geometry/triangulation.h"

namespace fmv3d::sfm {

void EvaluateInitialPair(const MapperImage& im1, const MapperImage& im2, core::Camera cam1, core::Camera cam2,
                         double focal_scale, const MapperOptions& opt, InitialPairCandidate* c) {
  constexpr double kDeg = M_PI / 180.0;
  c->evaluated = true;
  const auto& pair = *c->pair;
  auto normalized = [](const core::Camera& cam, const Eigen::Vector2d& uv) -> Eigen::Vector2d {
    return cam.Unproject(uv).head<2>();
  };
  auto normalise = [&](std::vector<cv::Point2d>* p1, std::vector<cv::Point2d>* p2) {
    p1->clear();
    p2->clear();
    for (const auto& m : pair.inliers) {
      const Eigen::Vector2d a = normalized(cam1, im1.keypoints[m.idx1]);
      const Eigen::Vector2d b = normalized(cam2, im2.keypoints[m.idx2]);
      p1->emplace_back(a.x(), a.y());
      p2->emplace_back(b.x(), b.y());
    }
  };
  std::vector<cv::Point2d> p1, p2, u1, u2;
  for (const auto& m : pair.inliers) {
    u1.emplace_back(im1.keypoints[m.idx1].x(), im1.keypoints[m.idx1].y());
    u2.emplace_back(im2.keypoints[m.idx2].x(), im2.keypoints[m.idx2].y());
  }
  c->focal_scale = focal_scale;
  cam1.f *= focal_scale;
  cam2.f *= focal_scale;
  normalise(&p1, &p2);
  if (p1.size() < 8) return;
  // Homography-dominated pairs (planar scene, pure rotation) give an unstable relative pose.
  if (pair.num_inliers_H > 0 && !pair.inliers.empty()) {
    c->h_ratio = static_cast<double>(pair.num_inliers_H) / pair.inliers.size();
  } else {
    cv::Mat hmask;
    const cv::Mat H = cv::findHomography(u1, u2, cv::RANSAC, 4.0, hmask, 2000, 0.999);
    c->h_ratio = H.empty() ? 0 : static_cast<double>(cv::countNonZero(hmask)) / p1.size();
  }
  const double f = 0.5 * (cam1.f + cam2.f);
  cv::Mat mask;
  cv::Mat E;
  try {
    E = cv::findEssentialMat(p1, p2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.9999, opt.tri_max_error_px / f, 5000,
                             mask);
  } catch (const cv::Exception&) {
    return;
  }
  if (E.rows != 3 || E.cols != 3) return;  // several solutions stacked or none: degenerate
  cv::Mat R, t;
  const int n_front = cv::recoverPose(E, p1, p2, cv::Mat::eye(3, 3, CV_64F), R, t, mask);
  if (n_front < opt.init_min_inliers / 2) return;
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  cv::cv2eigen(R, Re);
  cv::cv2eigen(t, te);
  c->pose2 = core::Pose(Eigen::Quaterniond(Re), te.normalized());
  const core::Pose pose1;
  std::vector<double> angles;
  for (size_t i = 0; i < p1.size(); ++i) {
    if (!mask.at<uint8_t>(static_cast<int>(i))) continue;
    const std::vector<core::Pose> poses = {pose1, c->pose2};
    const std::vector<Eigen::Vector2d> xs = {{p1[i].x, p1[i].y}, {p2[i].x, p2[i].y}};
    Eigen::Vector3d X;
    if (!geometry::TriangulateDLT(poses, xs, &X)) continue;
    if (!geometry::HasPositiveDepth(pose1, X) || !geometry::HasPositiveDepth(c->pose2, X)) continue;
    const double e1 = (cam1.Project(pose1.Transform(X)) - Eigen::Vector2d(u1[i].x, u1[i].y)).norm();
    const double e2 = (cam2.Project(c->pose2.Transform(X)) - Eigen::Vector2d(u2[i].x, u2[i].y)).norm();
    if (e1 > opt.tri_max_error_px || e2 > opt.tri_max_error_px) continue;
    angles.push_back(geometry::TriangulationAngle(pose1.Centre(), c->pose2.Centre(), X) / kDeg);
  }
  if (angles.size() < 8) return;
  std::nth_element(angles.begin(), angles.begin() + angles.size() / 2, angles.end());
  c->median_angle_deg = angles[angles.size() / 2];
  c->num_good = static_cast<int>(angles.size());
  c->valid = true;
}

}  // namespace fmv3d::sfm
