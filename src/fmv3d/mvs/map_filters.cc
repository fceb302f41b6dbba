#include "fmv3d/mvs/map_filters.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace fmv3d::mvs {

cv::Mat OccludingEdgeMask(const cv::Mat& depth, int radius_px, double depth_jump) {
  CV_Assert(depth.type() == CV_32F);
  cv::Mat mask = cv::Mat::zeros(depth.size(), CV_8U);
  if (radius_px <= 0) return mask;
  // The farthest depth within the radius (a disc): pixels without depth hold 0 and never win the max.
  cv::Mat farthest;
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * radius_px + 1, 2 * radius_px + 1));
  cv::dilate(depth, farthest, disc, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  const float k = static_cast<float>(1 + depth_jump);
  for (int y = 0; y < depth.rows; ++y) {
    const float* d = depth.ptr<float>(y);
    const float* f = farthest.ptr<float>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < depth.cols; ++x)
      if (d[x] > 0 && f[x] > k * d[x]) m[x] = 255;
  }
  return mask;
}

cv::Mat OccludingEdgeMask(const cv::Mat& depth, const cv::Mat& normal, const ViewGeometry& geom, int radius_px,
                          double depth_jump) {
  CV_Assert(normal.type() == CV_8SC3 && normal.size() == depth.size());
  // Candidates by the depth-only rule: the plane rule only ever clears pixels it marks.
  cv::Mat mask = OccludingEdgeMask(depth, radius_px, depth_jump);
  if (radius_px <= 0) return mask;
  std::vector<cv::Point> disc;
  for (int dy = -radius_px; dy <= radius_px; ++dy)
    for (int dx = -radius_px; dx <= radius_px; ++dx)
      if (dx * dx + dy * dy <= radius_px * radius_px + radius_px / 2 && (dx != 0 || dy != 0)) disc.emplace_back(dx, dy);
  const Eigen::Matrix3d Kinv = geom.K.inverse();
  const Eigen::Matrix3d R = geom.R;
  const double k = 1 + depth_jump;
  auto ray = [&](int x, int y) { return Eigen::Vector3d(Kinv * Eigen::Vector3d(x + 0.5, y + 0.5, 1)); };
  for (int y = 0; y < depth.rows; ++y) {
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < depth.cols; ++x) {
      if (!m[x]) continue;
      const double d = depth.at<float>(y, x);
      const cv::Vec<schar, 3>& c = normal.at<cv::Vec<schar, 3>>(y, x);
      const Eigen::Vector3d n = R * Eigen::Vector3d(c[0], c[1], c[2]);
      if (n.squaredNorm() < 1) continue;           // no normal: the depth-only verdict stands
      const double offset = n.dot(d * ray(x, y));  // the plane: n · X = offset (camera frame)
      bool edge = false;
      for (const cv::Point& o : disc) {
        const int qx = x + o.x, qy = y + o.y;
        if (qx < 0 || qy < 0 || qx >= depth.cols || qy >= depth.rows) continue;
        const double dq = depth.at<float>(qy, qx);
        if (!(dq > k * d)) continue;
        const double along = n.dot(ray(qx, qy));
        if (along * offset <= 0) continue;  // the plane does not meet this ray in front of the camera
        if (dq > k * (offset / along)) {    // behind p's surface continued: p occludes it
          edge = true;
          break;
        }
      }
      if (!edge) m[x] = 0;
    }
  }
  return mask;
}

std::vector<SparseDepth> SparseDepthsIn(const ViewGeometry& geom, const std::vector<SparseObservation>& sparse,
                                        double min_tolerance) {
  std::vector<SparseDepth> out;
  out.reserve(sparse.size());
  const double f = geom.K(0, 0);
  for (const auto& p : sparse) {
    Eigen::Vector2d uv;
    double z = 0;
    if (!geom.Project(p.xyz, &uv, &z)) continue;
    const double per_pixel = 1 / (f * std::max(std::sin(p.parallax_rad), 1e-6));
    out.push_back({uv.x(), uv.y(), z, std::max(min_tolerance, 3 * per_pixel)});
  }
  return out;
}

cv::Mat SparseContradictionMask(const cv::Mat& depth, const std::vector<SparseDepth>& sparse, double depth_jump,
                                int min_votes, size_t* pieces) {
  CV_Assert(depth.type() == CV_32F);
  cv::Mat mask = cv::Mat::zeros(depth.size(), CV_8U);
  if (pieces) *pieces = 0;
  if (sparse.empty()) return mask;
  // Pieces by flood fill (4-neighbours, depth continuous within depth_jump); label 0 = no depth.
  cv::Mat label = cv::Mat::zeros(depth.size(), CV_32S);
  int count = 0;
  std::vector<cv::Point> stack;
  const auto joined = [depth_jump](float a, float b) { return std::abs(a - b) <= depth_jump * std::min(a, b); };
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      if (!(depth.at<float>(y, x) > 0) || label.at<int>(y, x) != 0) continue;
      label.at<int>(y, x) = ++count;
      stack.assign(1, cv::Point(x, y));
      while (!stack.empty()) {
        const cv::Point p = stack.back();
        stack.pop_back();
        const float d = depth.at<float>(p);
        for (const cv::Point q :
             {cv::Point(p.x + 1, p.y), cv::Point(p.x - 1, p.y), cv::Point(p.x, p.y + 1), cv::Point(p.x, p.y - 1)}) {
          if (q.x < 0 || q.y < 0 || q.x >= depth.cols || q.y >= depth.rows || label.at<int>(q) != 0) continue;
          const float e = depth.at<float>(q);
          if (e > 0 && joined(d, e)) {
            label.at<int>(q) = count;
            stack.push_back(q);
          }
        }
      }
    }
  std::vector<int> agree(count + 1, 0), disagree(count + 1, 0);
  for (const auto& s : sparse) {
    const double u = std::floor(s.u), v = std::floor(s.v);
    if (!(s.depth > 0) || u < 0 || v < 0 || u >= depth.cols || v >= depth.rows) continue;
    const cv::Point p(static_cast<int>(u), static_cast<int>(v));
    const int l = label.at<int>(p);
    if (l == 0) continue;
    (std::abs(depth.at<float>(p) - s.depth) <= s.tolerance * s.depth ? agree : disagree)[l]++;
  }
  std::vector<uint8_t> drop(count + 1, 0);
  for (int l = 1; l <= count; ++l) {
    drop[l] = disagree[l] >= min_votes && disagree[l] > agree[l];
    if (pieces) *pieces += drop[l];
  }
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x)
      if (drop[label.at<int>(y, x)]) mask.at<uint8_t>(y, x) = 255;
  return mask;
}

}  // namespace fmv3d::mvs
