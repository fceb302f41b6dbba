#include "fmv3d/features/sift.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <tuple>

#include "fmv3d/core/error.h"

namespace fmv3d::features {

void SiftOptions::Check() const {
  if (max_features < 0) throw Error("features: --max-features must be >= 0");
  if (max_image_size < 64) throw Error("features: --max-image-size must be >= 64");
  if (!(contrast_threshold > 0 && contrast_threshold < 1))
    throw Error("features: --contrast-threshold must be in (0, 1)");
  if (!(edge_threshold > 1)) throw Error("features: --edge-threshold must be > 1");
  if (octave_layers < 1 || octave_layers > 8) throw Error("features: --octave-layers must be in [1, 8]");
  if (min_features < 0) throw Error("features: minimum features must be >= 0");
  if (!(min_coverage >= 0 && min_coverage <= 1)) throw Error("features: minimum coverage must be in [0, 1]");
  if (!(min_contrast_threshold > 0)) throw Error("features: minimum contrast threshold must be > 0");
  if (!(max_memory_mb > 0)) throw Error("features: --max-memory must be > 0 MB");
}

void QuantiseDescriptors(const cv::Mat& d, bool root_sift, Descriptors* out) {
  out->resize(d.rows, 128);
  for (int i = 0; i < d.rows; ++i) {
    const float* row = d.ptr<float>(i);
    float v[128];
    if (root_sift) {
      double l1 = 0;
      for (int k = 0; k < 128; ++k) l1 += std::abs(row[k]);
      const double inv = l1 > 0 ? 1.0 / l1 : 0;
      for (int k = 0; k < 128; ++k) v[k] = static_cast<float>(std::sqrt(std::abs(row[k]) * inv));
    } else {
      double l2 = 0;
      for (int k = 0; k < 128; ++k) l2 += double(row[k]) * row[k];
      const double inv = l2 > 0 ? 1.0 / std::sqrt(l2) : 0;
      for (int k = 0; k < 128; ++k) v[k] = static_cast<float>(row[k] * inv);
    }
    for (int k = 0; k < 128; ++k) (*out)(i, k) = static_cast<uint8_t>(std::min(255.0f, std::round(512.0f * v[k])));
  }
}

Descriptors DescribeAt(const cv::Mat& image, const std::vector<Keypoint>& keypoints, bool root_sift) {
  Descriptors out(0, 128);
  if (keypoints.empty()) return out;
  cv::Mat grey;
  if (image.channels() == 1)
    grey = image;
  else
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  // The inverse of ExtractSift's conversion (OpenCV's centres at integers and its 0.25 px offset).
  std::vector<cv::KeyPoint> kps;
  kps.reserve(keypoints.size());
  for (const auto& k : keypoints)
    kps.emplace_back(cv::Point2f(k.x - 0.25f, k.y - 0.25f), std::max(2.0f, 2 * k.scale), 0.0f);
  cv::Mat desc;
  cv::SIFT::create()->compute(grey, kps, desc);
  if (desc.rows != static_cast<int>(keypoints.size())) {
    // OpenCV drops keypoints it cannot describe (too close to the border): describe them one by one.
    cv::Mat all = cv::Mat::zeros(static_cast<int>(keypoints.size()), 128, CV_32F);
    for (size_t i = 0; i < keypoints.size(); ++i) {
      std::vector<cv::KeyPoint> one = {cv::KeyPoint(cv::Point2f(keypoints[i].x - 0.25f, keypoints[i].y - 0.25f),
                                                    std::max(2.0f, 2 * keypoints[i].scale), 0.0f)};
      cv::Mat d;
      cv::SIFT::create()->compute(grey, one, d);
      if (d.rows == 1) d.copyTo(all.row(static_cast<int>(i)));
    }
    desc = all;
  }
  QuantiseDescriptors(desc, root_sift, &out);
  return out;
}

double KeypointCoverage(const std::vector<Keypoint>& keypoints, int width, int height, int grid) {
  if (width <= 0 || height <= 0 || grid <= 0) return 0;
  std::vector<char> hit(static_cast<size_t>(grid) * grid, 0);
  for (const auto& k : keypoints) {
    const int cx = std::clamp(static_cast<int>(k.x * grid / width), 0, grid - 1);
    const int cy = std::clamp(static_cast<int>(k.y * grid / height), 0, grid - 1);
    hit[static_cast<size_t>(cy) * grid + cx] = 1;
  }
  return static_cast<double>(std::count(hit.begin(), hit.end(), 1)) / hit.size();
}

namespace {

cv::Mat ToGrey(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 1) {
    grey = image;
  } else if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  }
  return grey;
}

// Keypoints (OpenCV's pixels of the image given) and float descriptors of one SIFT call.
struct SiftResult {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
};

SiftResult DetectWhole(const cv::Mat& grey, const SiftOptions& options, double threshold) {
  auto sift =
      cv::SIFT::create(options.max_features, options.octave_layers, threshold, options.edge_threshold, 1.6, CV_32F);
  SiftResult r;
  if (!options.upright) {
    sift->detectAndCompute(grey, cv::noArray(), r.keypoints, r.descriptors);
    return r;
  }
  std::vector<cv::KeyPoint> kps;
  sift->detect(grey, kps);
  // One keypoint per location/scale with orientation 0 (OpenCV's detector duplicates a keypoint for each
  // dominant orientation).
  std::map<std::tuple<float, float, float>, cv::KeyPoint> unique;
  for (auto k : kps) {
    k.angle = 0;
    auto key = std::make_tuple(k.pt.x, k.pt.y, k.size);
    auto it = unique.find(key);
    if (it == unique.end() || it->second.response < k.response) unique[key] = k;
  }
  for (auto& [key, k] : unique) r.keypoints.push_back(k);
  sift->compute(grey, r.keypoints, r.descriptors);
  return r;
}

// SIFT on each tile's window, keeping the keypoints that lie in its core (shifted to the whole image), in a
// canonical order (position, size, angle) so that the result does not depend on the tiling's order.
SiftResult DetectTiled(const cv::Mat& grey, const std::vector<SiftTile>& tiles, const SiftOptions& options,
                       double threshold) {
  std::vector<cv::KeyPoint> kps;
  cv::Mat rows;  // copies: a tile's whole descriptor matrix is freed once its core's rows are taken
  for (const auto& t : tiles) {
    // A copy: OpenCV's filters would otherwise read the pixels around a sub-matrix as its border.
    const cv::Mat window = grey(cv::Rect(t.window.x, t.window.y, t.window.width, t.window.height)).clone();
    const SiftResult part = DetectWhole(window, options, threshold);
    for (size_t i = 0; i < part.keypoints.size(); ++i) {
      cv::KeyPoint k = part.keypoints[i];
      k.pt.x += static_cast<float>(t.window.x);
      k.pt.y += static_cast<float>(t.window.y);
      if (k.pt.x < t.core.x || k.pt.x >= t.core.x + t.core.width || k.pt.y < t.core.y ||
          k.pt.y >= t.core.y + t.core.height)
        continue;
      kps.push_back(k);
      rows.push_back(part.descriptors.row(static_cast<int>(i)));
    }
  }
  std::vector<int> order(kps.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  auto key = [&](int i) { return std::make_tuple(kps[i].pt.x, kps[i].pt.y, kps[i].size, kps[i].angle); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key(a) < key(b); });
  SiftResult r;
  r.descriptors.create(static_cast<int>(order.size()), 128, CV_32F);
  for (size_t i = 0; i < order.size(); ++i) {
    r.keypoints.push_back(kps[order[i]]);
    rows.row(order[i]).copyTo(r.descriptors.row(static_cast<int>(i)));
  }
  return r;
}

// Detection at falling contrast thresholds until the keypoints are many and spread enough (SiftOptions).
SiftResult DetectAdaptive(const cv::Mat& grey, const std::vector<SiftTile>& tiles, const SiftOptions& options,
                          double* threshold_used) {
  double threshold = options.contrast_threshold;
  for (;;) {
    SiftResult r =
        tiles.size() > 1 ? DetectTiled(grey, tiles, options, threshold) : DetectWhole(grey, options, threshold);
    bool done = options.min_features <= 0 || threshold * 0.5 < options.min_contrast_threshold;
    if (!done) {
      std::vector<Keypoint> where(r.keypoints.size());
      for (size_t i = 0; i < r.keypoints.size(); ++i) where[i] = {r.keypoints[i].pt.x, r.keypoints[i].pt.y, 0, 0};
      done = static_cast<int>(r.keypoints.size()) >= options.min_features &&
             KeypointCoverage(where, grey.cols, grey.rows) >= options.min_coverage;
    }
    if (done) {
      *threshold_used = threshold;
      return r;
    }
    threshold *= 0.5;
  }
}

// OpenCV's cap keeps ties at the threshold response: enforce it exactly (strongest first, stable).
void KeepStrongest(int max_features, SiftResult* r) {
  auto& kps = r->keypoints;
  if (max_features <= 0 || static_cast<int>(kps.size()) <= max_features) return;
  std::vector<int> order(kps.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return kps[a].response > kps[b].response; });
  order.resize(max_features);
  std::sort(order.begin(), order.end());
  std::vector<cv::KeyPoint> kept;
  cv::Mat kept_desc(static_cast<int>(order.size()), r->descriptors.cols, r->descriptors.type());
  for (size_t i = 0; i < order.size(); ++i) {
    kept.push_back(kps[order[i]]);
    r->descriptors.row(order[i]).copyTo(kept_desc.row(static_cast<int>(i)));
  }
  kps.swap(kept);
  r->descriptors = kept_desc;
}

Eigen::Matrix<uint8_t, 3, 1> ColourAt(const cv::Mat& image, int r, int c) {
  if (image.channels() == 1) {
    const uint8_t g = image.at<uint8_t>(r, c);
    return {g, g, g};
  }
  if (image.channels() == 3) {
    const auto& bgr = image.at<cv::Vec3b>(r, c);
    return {bgr[2], bgr[1], bgr[0]};
  }
  const auto& bgra = image.at<cv::Vec4b>(r, c);
  return {bgra[2], bgra[1], bgra[0]};
}

}  // namespace

FeatureSet ExtractSift(const cv::Mat& image, const SiftOptions& options, double* contrast_threshold_used,
                       const std::vector<SiftTile>& tiles) {
  if (image.empty() || image.depth() != CV_8U) throw Error("features: empty or non-8-bit image");
  FeatureSet out;
  out.width = image.cols;
  out.height = image.rows;
  cv::Mat grey = ToGrey(image);
  int width = image.cols, height = image.rows;
  ExtractionSize(image.cols, image.rows, options.max_image_size, &width, &height);
  if (width != image.cols || height != image.rows) {
    const double scale = double(options.max_image_size) / std::max(image.cols, image.rows);
    cv::Mat small;
    cv::resize(grey, small, cv::Size(), scale, scale, cv::INTER_AREA);
    grey = small;
    // INTER_AREA may round the size; use the exact ratio per axis for coordinates below.
  }
  const double sx = double(grey.cols) / image.cols, sy = double(grey.rows) / image.rows;
  for (const auto& t : tiles)
    if (t.window.x < 0 || t.window.y < 0 || t.window.x + t.window.width > grey.cols ||
        t.window.y + t.window.height > grey.rows)
      throw Error("features: a SIFT tile lies outside the extraction image");

  double threshold = options.contrast_threshold;
  SiftResult found = DetectAdaptive(grey, tiles, options, &threshold);
  if (contrast_threshold_used) *contrast_threshold_used = threshold;
  KeepStrongest(options.max_features, &found);
  QuantiseDescriptors(found.descriptors, options.root_sift, &out.descriptors);
  const auto& kps = found.keypoints;
  out.keypoints.resize(kps.size());
  out.colors.resize(kps.size());
  for (size_t i = 0; i < kps.size(); ++i) {
    const auto& k = kps[i];
    auto& o = out.keypoints[i];
    // OpenCV pixel centres are integers; ours are at +0.5. OpenCV's SIFT also reports every keypoint 0.25 px
    // right and down of where it is: it doubles the image with a centre-aligned resize (doubled pixel X sits at
    // X/2 − 0.25) but halves coordinates as X/2, and its coarser octaves subsample that grid. A shift common to
    // all images costs nothing in reprojection error but rotates every camera alike (test
    // KeypointsHaveNoCommonOffset). Then map through the extraction scale.
    constexpr double kOpenCvSiftOffset = 0.25;
    o.x = static_cast<float>((k.pt.x + 0.5 - kOpenCvSiftOffset) / sx);
    o.y = static_cast<float>((k.pt.y + 0.5 - kOpenCvSiftOffset) / sy);
    o.scale = static_cast<float>(0.5 * k.size / std::sqrt(sx * sy));
    o.orientation = static_cast<float>(k.angle * M_PI / 180.0);
    const int c = std::clamp(static_cast<int>(o.x), 0, image.cols - 1);
    const int r = std::clamp(static_cast<int>(o.y), 0, image.rows - 1);
    out.colors[i] = ColourAt(image, r, c);
  }
  return out;
}

}  // namespace fmv3d::features
