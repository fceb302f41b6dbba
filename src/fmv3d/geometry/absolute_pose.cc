#include "fmv3d/geometry/absolute_pose.h"

#include <ceres/ceres.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/reprojection_error.h"

namespace fmv3d::geometry {

void AbsolutePoseOptions::Check() const {
  if (!(max_error_px > 0)) throw Error("absolute pose: max_error_px must be > 0");
  if (!(confidence > 0 && confidence < 1)) throw Error("absolute pose: confidence must be in (0, 1)");
  if (max_iterations < 1) throw Error("absolute pose: max_iterations must be ≥ 1");
  if (min_inliers < 4) throw Error("absolute pose: min_inliers must be ≥ 4");
}

namespace {

void CountInliers(const std::vector<Eigen::Vector2d>& p2, const std::vector<Eigen::Vector3d>& p3,
                  const core::Camera& cam, const core::Pose& pose, double thr, AbsolutePoseResult* r) {
  r->inlier_mask.assign(p2.size(), 0);
  r->num_inliers = 0;
  double sum = 0;
  for (size_t i = 0; i < p2.size(); ++i) {
    const Eigen::Vector3d x = pose.Transform(p3[i]);
    if (x.z() <= 0) continue;
    const double e = (cam.Project(x) - p2[i]).norm();
    if (e < thr) {
      r->inlier_mask[i] = 1;
      ++r->num_inliers;
      sum += e;
    }
  }
  r->mean_inlier_error_px = r->num_inliers ? sum / r->num_inliers : 0;
}

}  // namespace

bool RefineAbsolutePose(const std::vector<Eigen::Vector2d>& points2d, const std::vector<Eigen::Vector3d>& points3d,
                        core::Camera* camera, core::Pose* pose, bool refine_focal, bool refine_k1,
                        double loss_scale_px) {
  if (points2d.size() < 4 || points2d.size() != points3d.size()) return false;
  auto intr = camera->Params();
  double q[4] = {pose->q.x(), pose->q.y(), pose->q.z(), pose->q.w()};
  double t[3] = {pose->t.x(), pose->t.y(), pose->t.z()};
  ceres::Problem problem;
  for (size_t i = 0; i < points2d.size(); ++i)
    problem.AddResidualBlock(PoseOnlyReprojectionError::Create(points2d[i], points3d[i]),
                             new ceres::CauchyLoss(loss_scale_px), intr.data(), q, t);
  problem.SetManifold(q, new ceres::EigenQuaternionManifold);
  std::vector<int> fixed;
  for (int k = 0; k < core::kNumIntrinsics; ++k)
    if (!((k == core::kF && refine_focal) || (k == core::kK1 && refine_k1))) fixed.push_back(k);
  if (fixed.size() == core::kNumIntrinsics)
    problem.SetParameterBlockConstant(intr.data());
  else
    problem.SetManifold(intr.data(), new ceres::SubsetManifold(core::kNumIntrinsics, fixed));
  ceres::Solver::Options opts;
  opts.linear_solver_type = ceres::DENSE_QR;
  opts.max_num_iterations = 100;
  opts.function_tolerance = 1e-8;
  opts.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(opts, &problem, &summary);
  if (!summary.IsSolutionUsable()) return false;
  pose->q = Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized();
  pose->t = Eigen::Vector3d(t[0], t[1], t[2]);
  camera->SetParams(intr.data());
  return true;
}

AbsolutePoseResult EstimateAbsolutePose(const std::vector<Eigen::Vector2d>& points2d,
                                        const std::vector<Eigen::Vector3d>& points3d, const core::Camera& camera,
                                        const AbsolutePoseOptions& options) {
  options.Check();
  AbsolutePoseResult result;
  result.camera = camera;
  const size_t n = points2d.size();
  if (n < static_cast<size_t>(std::max(options.min_inliers, 4)) || points3d.size() != n) return result;

  // Undistorted "ideal pixels" f·(x, y): RANSAC thresholds stay in pixels while AP3P sees a pinhole camera.
  const double f = camera.f;
  std::vector<cv::Point2d> img(n);
  std::vector<cv::Point3d> obj(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d ray = camera.Unproject(points2d[i]);
    img[i] = cv::Point2d(f * ray.x(), f * ray.y());
    obj[i] = cv::Point3d(points3d[i].x(), points3d[i].y(), points3d[i].z());
  }
  const cv::Matx33d K(f, 0, 0, 0, f, 0, 0, 0, 1);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  bool ok = false;
  try {
    ok = cv::solvePnPRansac(obj, img, K, cv::noArray(), rvec, tvec, false, options.max_iterations,
                            static_cast<float>(options.max_error_px), options.confidence, inliers, cv::SOLVEPNP_AP3P);
  } catch (const cv::Exception&) {
    ok = false;  // degenerate input (e.g. all points identical): a failed registration, not a crash
  }
  if (!ok || static_cast<int>(inliers.size()) < options.min_inliers) return result;

  cv::Mat Rcv;
  cv::Rodrigues(rvec, Rcv);
  Eigen::Matrix3d R;
  cv::cv2eigen(Rcv, R);
  Eigen::Vector3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  core::Pose pose(Eigen::Quaterniond(R), t);
  core::Camera cam = camera;
  CountInliers(points2d, points3d, cam, pose, options.max_error_px, &result);

  if (options.refine && result.num_inliers >= 4) {
    // Two rounds: refine on the inliers, re-select inliers with the refined model.
    for (int round = 0; round < 2; ++round) {
      std::vector<Eigen::Vector2d> a;
      std::vector<Eigen::Vector3d> b;
      for (size_t i = 0; i < n; ++i)
        if (result.inlier_mask[i]) {
          a.push_back(points2d[i]);
          b.push_back(points3d[i]);
        }
      core::Pose p2 = pose;
      core::Camera c2 = cam;
      const bool free_intr = a.size() >= 30;  // too few points cannot carry a focal estimate
      if (!RefineAbsolutePose(a, b, &c2, &p2, options.refine_focal && free_intr, options.refine_k1 && free_intr)) break;
      if (!(c2.f > 0)) break;
      pose = p2;
      cam = c2;
      CountInliers(points2d, points3d, cam, pose, options.max_error_px, &result);
    }
  }
  result.pose = pose;
  result.camera = cam;
  result.success = result.num_inliers >= options.min_inliers &&
                   result.num_inliers >= options.min_inlier_ratio * static_cast<double>(n);
  return result;
}

}  // namespace fmv3d::geometry
