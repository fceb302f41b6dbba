#include "fmv3d/sfm/focal_scan.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <vector>

namespace fmv3d::sfm {

namespace {

// Mean truncated squared Sampson error (px²) of E over normalised points; f converts to pixels.
double MsacScore(const Eigen::Matrix3d& E, const std::vector<cv::Point2d>& p1, const std::vector<cv::Point2d>& p2,
                 double f, double threshold_px) {
  const double t2 = threshold_px * threshold_px;
  double sum = 0;
  for (size_t i = 0; i < p1.size(); ++i) {
    const Eigen::Vector3d a(p1[i].x, p1[i].y, 1), b(p2[i].x, p2[i].y, 1);
    const Eigen::Vector3d Ea = E * a, Etb = E.transpose() * b;
    const double num = b.dot(Ea);
    const double den = Ea.head<2>().squaredNorm() + Etb.head<2>().squaredNorm();
    const double e2 = den > 0 ? f * f * num * num / den : t2;
    sum += std::min(e2, t2);
  }
  return sum / std::max<size_t>(1, p1.size());
}

// Median of each value and its two neighbours (at the ends, of the first or last three).
std::vector<double> MedianOfNeighbours(const std::vector<double>& v) {
  if (v.size() < 3) return v;
  std::vector<double> m(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    const size_t c = std::clamp<size_t>(i, 1, v.size() - 2);
    const double a = v[c - 1], b = v[c], d = v[c + 1];
    m[i] = std::max(std::min(a, b), std::min(std::max(a, b), d));
  }
  return m;
}

}  // namespace

FocalScanResult ScanFocal(const core::Camera& camera, const std::vector<FocalScanPair>& pairs,
                          const FocalScanOptions& o) {
  FocalScanResult r;
  r.focal = camera.f;
  bool any = false;
  for (const auto& p : pairs) any = any || (p.uv1.size() >= 8 && p.uv1.size() == p.uv2.size());
  if (!any) return r;
  for (double k = o.min_factor; k <= o.max_factor * 1.0001; k *= o.step) r.focals.push_back(camera.f * k);
  r.scores.assign(r.focals.size(), 0.0);
  std::vector<cv::Point2d> p1, p2, q1, q2;
  for (size_t c = 0; c < r.focals.size(); ++c) {
    core::Camera cam = camera;
    cam.f = r.focals[c];
    const cv::Matx33d K(cam.fx(), 0, cam.u0, 0, cam.fy(), cam.v0, 0, 0, 1);
    for (const auto& pr : pairs) {
      if (pr.uv1.size() < 8 || pr.uv1.size() != pr.uv2.size()) continue;
      p1.clear();
      p2.clear();
      q1.clear();
      q2.clear();
      for (size_t i = 0; i < pr.uv1.size(); ++i) {
        const Eigen::Vector2d a = cam.Unproject(pr.uv1[i]).head<2>();  // z = 1
        const Eigen::Vector2d b = cam.Unproject(pr.uv2[i]).head<2>();
        p1.emplace_back(a.x(), a.y());
        p2.emplace_back(b.x(), b.y());
        // Undistorted pixels for the estimator, so its threshold is in pixels at every candidate focal.
        q1.emplace_back(cam.fx() * a.x() + cam.u0, cam.fy() * a.y() + cam.v0);
        q2.emplace_back(cam.fx() * b.x() + cam.u0, cam.fy() * b.y() + cam.v0);
      }
      double best = o.threshold_px * o.threshold_px;  // no model: every match counts as an outlier
      // USAC with MSAC scoring and local optimisation: plain RANSAC's luck shows up as score noise between
      // neighbouring candidates, larger than the differences the scan looks for.
      cv::UsacParams up;
      up.confidence = 0.999;
      up.maxIterations = o.ransac_iterations;
      up.threshold = o.threshold_px;
      up.loMethod = cv::LOCAL_OPTIM_INNER_LO;
      up.score = cv::SCORE_METHOD_MSAC;
      up.sampler = cv::SAMPLING_UNIFORM;
      up.randomGeneratorState = static_cast<int>(o.seed);
      up.isParallel = false;
      cv::Mat E, mask;
      try {
        E = cv::findEssentialMat(q1, q2, K, K, cv::noArray(), cv::noArray(), mask, up);
      } catch (const cv::Exception&) {
        E = cv::Mat();
      }
      // Several solutions may come stacked (3k x 3): the best of them scores the candidate.
      for (int s = 0; s + 3 <= E.rows && E.cols == 3; s += 3) {
        Eigen::Matrix3d Ee;
        cv::cv2eigen(E.rowRange(s, s + 3), Ee);
        best = std::min(best, MsacScore(Ee, p1, p2, cam.f, o.threshold_px));
      }
      r.scores[c] += best;
    }
  }
  // Flat: every candidate explains the matches about equally well (optical axes that meet, as in an orbit around its
  // target, or near-affine views), and the best is one candidate's luck (a lucky or failed minimal sample; at very
  // long focals the five-point solver degenerates). Two views bound nothing: the shortest candidate is the lower
  // bound, and the multi-view dolly-zoom scan decides from there. The flatness test reads the median of each
  // candidate and its neighbours, so one such jump does not decide it.
  const std::vector<double> smooth = MedianOfNeighbours(r.scores);
  const auto [lo, hi] = std::minmax_element(smooth.begin(), smooth.end());
  if (*hi <= (1 + o.flat_tolerance) * *lo) {
    r.undetermined = r.plateau = true;
    r.focal = r.focals.front();
    return r;
  }
  const double best = *std::min_element(r.scores.begin(), r.scores.end());
  const double limit = (1 + o.tolerance) * best + 1e-12;
  size_t chosen = 0;
  while (chosen + 1 < r.scores.size() && r.scores[chosen] > limit) ++chosen;
  r.focal = r.focals[chosen];
  r.plateau = r.scores.back() <= limit;
  return r;
}

}  // namespace fmv3d::sfm
