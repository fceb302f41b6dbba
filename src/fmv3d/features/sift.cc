#include "fmv3d/features/sift.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

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

FeatureSet ExtractSift(const cv::Mat& image, const SiftOptions& options, double* contrast_threshold_used) {
  if (image.empty() || image.depth() != CV_8U) throw Error("features: empty or non-8-bit image");
  FeatureSet out;
  out.width = image.cols;
  out.height = image.rows;
  cv::Mat grey;
  if (image.channels() == 1) {
    grey = image;
  } else if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  }
  const int max_dim = std::max(image.cols, image.rows);
  double scale = 1;  // extraction image = scale * full image
  if (max_dim > options.max_image_size) {
    scale = double(options.max_image_size) / max_dim;
    cv::Mat small;
    cv::resize(grey, small, cv::Size(), scale, scale, cv::INTER_AREA);
    grey = small;
    // INTER_AREA may round the size; use the exact ratio per axis for coordinates below.
  }
  const double sx = double(grey.cols) / image.cols, sy = double(grey.rows) / image.rows;

  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  double threshold = options.contrast_threshold;
  for (;;) {
    auto sift =
        cv::SIFT::create(options.max_features, options.octave_layers, threshold, options.edge_threshold, 1.6, CV_32F);
    kps.clear();
    desc = cv::Mat();
    if (!options.upright) {
      sift->detectAndCompute(grey, cv::noArray(), kps, desc);
    } else {
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
      kps.clear();
      for (auto& [key, k] : unique) kps.push_back(k);
      sift->compute(grey, kps, desc);
    }
    if (options.min_features <= 0 || threshold * 0.5 < options.min_contrast_threshold) break;
    std::vector<Keypoint> where(kps.size());
    for (size_t i = 0; i < kps.size(); ++i) where[i] = {kps[i].pt.x, kps[i].pt.y, 0, 0};
    if (static_cast<int>(kps.size()) >= options.min_features &&
        KeypointCoverage(where, grey.cols, grey.rows) >= options.min_coverage)
      break;
    threshold *= 0.5;
  }
  if (contrast_threshold_used) *contrast_threshold_used = threshold;
  // OpenCV's cap keeps ties at the threshold response: enforce it exactly (strongest first, stable).
  if (options.max_features > 0 && static_cast<int>(kps.size()) > options.max_features) {
    std::vector<int> order(kps.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return kps[a].response > kps[b].response; });
    order.resize(options.max_features);
    std::sort(order.begin(), order.end());
    std::vector<cv::KeyPoint> kept;
    cv::Mat kept_desc(static_cast<int>(order.size()), desc.cols, desc.type());
    for (size_t i = 0; i < order.size(); ++i) {
      kept.push_back(kps[order[i]]);
      desc.row(order[i]).copyTo(kept_desc.row(static_cast<int>(i)));
    }
    kps.swap(kept);
    desc = kept_desc;
  }
  QuantiseDescriptors(desc, options.root_sift, &out.descriptors);
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
    if (image.channels() == 1) {
      const uint8_t g = image.at<uint8_t>(r, c);
      out.colors[i] = {g, g, g};
    } else if (image.channels() == 3) {
      const auto& bgr = image.at<cv::Vec3b>(r, c);
      out.colors[i] = {bgr[2], bgr[1], bgr[0]};
    } else {
      const auto& bgra = image.at<cv::Vec4b>(r, c);
      out.colors[i] = {bgra[2], bgra[1], bgra[0]};
    }
  }
  return out;
}

FeaturesStageStats RunFeaturesStage(const core::Workspace& ws, const SiftOptions& options, bool force) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  const fs::path frames_dir = ws.frames_dir(), features_dir = ws.features_dir();
  const auto index = io::ReadFramesIndex(ws.frames_json());
  core::EnsureDirectory(features_dir);
  const size_t n = index.frames.size();
  std::vector<size_t> counts(n, 0);
  std::vector<int> skipped(n, 0), adapted(n, 0);
  std::vector<double> thresholds(n, options.contrast_threshold);
  std::vector<std::string> errors(n);

  // Parallelism is over images; OpenCV's own parallel_for inside SIFT would oversubscribe the cores.
  const int cv_threads = cv::getNumThreads();
  cv::setNumThreads(1);
  core::Progress progress("features", n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    const auto& frame = index.frames[i];
    const fs::path image_path = frames_dir / frame.name;
    const fs::path out_path = FeaturePath(features_dir, frame.name);
    try {
      std::error_code ec;
      if (!force && fs::exists(out_path, ec) &&
          fs::last_write_time(out_path, ec) >= fs::last_write_time(image_path, ec) && !ec) {
        counts[i] = ReadFeatures(out_path).keypoints.size();
        skipped[i] = 1;
      } else {
        const cv::Mat image = cv::imread(image_path.string(), cv::IMREAD_COLOR);
        if (image.empty()) throw Error(image_path.string() + ": cannot read image");
        double used = options.contrast_threshold;
        auto features = ExtractSift(image, options, &used);
        adapted[i] = used < options.contrast_threshold;
        thresholds[i] = used;
        features.image_name = frame.name;
        counts[i] = features.keypoints.size();
        WriteFeatures(features, out_path);
      }
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
    progress.Add();
  });
  progress.Finish();
  cv::setNumThreads(cv_threads);
  for (const auto& e : errors)
    if (!e.empty()) throw Error(e);

  FeaturesStageStats stats;
  stats.images = n;
  stats.min_keypoints = n ? *std::min_element(counts.begin(), counts.end()) : 0;
  stats.max_keypoints = n ? *std::max_element(counts.begin(), counts.end()) : 0;
  for (size_t c : counts) stats.total_keypoints += c;
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  size_t num_skipped = 0;
  nlohmann::json per_image = nlohmann::json::array();
  for (size_t i = 0; i < n; ++i) {
    num_skipped += skipped[i];
    stats.adapted_images += adapted[i];
    per_image.push_back({{"name", index.frames[i].name}, {"keypoints", counts[i]}});
    if (adapted[i]) per_image.back()["contrast_threshold"] = thresholds[i];
  }
  nlohmann::json summary = {{"images", n},
                            {"skipped_up_to_date", num_skipped},
                            {"total_keypoints", stats.total_keypoints},
                            {"min_keypoints", stats.min_keypoints},
                            {"max_keypoints", stats.max_keypoints},
                            {"adapted_contrast_images", stats.adapted_images},
                            {"mean_keypoints", n ? double(stats.total_keypoints) / n : 0.0},
                            {"seconds", stats.seconds},
                            {"options",
                             {{"max_features", options.max_features},
                              {"max_image_size", options.max_image_size},
                              {"contrast_threshold", options.contrast_threshold},
                              {"edge_threshold", options.edge_threshold},
                              {"root_sift", options.root_sift},
                              {"upright", options.upright},
                              {"min_features", options.min_features},
                              {"min_coverage", options.min_coverage},
                              {"min_contrast_threshold", options.min_contrast_threshold}}},
                            {"per_image", per_image}};
  core::WriteJson(features_dir / "features.json", summary);
  spdlog::info("features: {} images, {} keypoints (min {}, max {}), {:.1f} s{}", n, stats.total_keypoints,
               stats.min_keypoints, stats.max_keypoints, stats.seconds,
               stats.adapted_images
                   ? fmt::format("; contrast threshold lowered on {} weak images", stats.adapted_images)
                   : std::string());
  return stats;
}

}  // namespace fmv3d::features
