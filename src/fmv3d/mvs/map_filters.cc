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
