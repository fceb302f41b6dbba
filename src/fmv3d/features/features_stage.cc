// The `fmv3d features` stage (declared in sift.h): SIFT over every frame, in parallel within the memory budget.
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/sift.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/huge_pages.h"

namespace fmv3d::features {
namespace fs = std::filesystem;
namespace {

struct ImageResult {
  size_t keypoints = 0;
  int skipped = 0, adapted = 0;
  double threshold = 0;
  std::string error;
};

// The frame's size from its camera in frames.json (0 x 0 when unknown: then planned once decoded).
SiftMemoryPlan PlanFrame(const io::FramesIndex& index, const io::FrameRecord& frame, const SiftOptions& options,
                         double budget) {
  const io::CameraPrior* camera = index.FindCamera(frame.camera_id);
  if (!camera || camera->camera.width <= 0 || camera->camera.height <= 0) return {};
  return PlanSiftMemory(camera->camera.width, camera->camera.height, options, budget);
}

bool UpToDate(const fs::path& out_path, const fs::path& image_path) {
  std::error_code ec;
  return fs::exists(out_path, ec) && fs::last_write_time(out_path, ec) >= fs::last_write_time(image_path, ec) && !ec;
}

cv::Mat ReadImage(const fs::path& image_path) {
  cv::Mat image = cv::imread(image_path.string(), cv::IMREAD_COLOR);
  if (image.empty()) throw Error(image_path.string() + ": cannot read image");
  return image;
}

// Extracts one frame under the gate (its estimate held from before decoding to the written .feat). A frame whose
// size frames.json does not give is decoded first, then planned and admitted.
void ExtractFrame(const fs::path& image_path, const fs::path& out_path, const std::string& name,
                  const SiftOptions& options, double budget, SiftMemoryPlan plan, MemoryGate* gate, ImageResult* r) {
  cv::Mat image;
  if (plan.extraction_width == 0) {
    image = ReadImage(image_path);
    plan = PlanSiftMemory(image.cols, image.rows, options, budget);
  }
  const double held = plan.estimated_bytes;
  gate->Acquire(held);
  try {
    if (image.empty()) image = ReadImage(image_path);
    int w = 0, h = 0;
    ExtractionSize(image.cols, image.rows, options.max_image_size, &w, &h);
    if (w != plan.extraction_width || h != plan.extraction_height)  // frames.json's size was not the image's
      plan = PlanSiftMemory(image.cols, image.rows, options, budget);
    double used = options.contrast_threshold;
    auto features = ExtractSift(image, options, &used, plan.tiles);
    image.release();
#ifdef __GLIBC__
    // The pyramid's smaller levels come from the heap: hand them back, or each worker's arena keeps its own.
    malloc_trim(0);
#endif
    r->adapted = used < options.contrast_threshold;
    r->threshold = used;
    features.image_name = name;
    features.contrast_threshold = used;
    r->keypoints = features.keypoints.size();
    WriteFeatures(features, out_path);
  } catch (...) {
    gate->Release(held);
    throw;
  }
  gate->Release(held);
}

// The plan only: how many images were in flight at the peak depends on thread timing and on how many were up to
// date from an interrupted run, so it is logged, not written (a resumed run writes the same summary).
nlohmann::json MemoryJson(const SiftOptions& options, const FeaturesStageStats& s) {
  return {{"max_memory_mb", options.max_memory_mb},
          {"estimated_image_mb", s.max_image_bytes / 1048576.0},
          {"workers", s.workers},
          {"tiled_images", s.tiled_images},
          {"max_tiles", s.max_tiles}};
}

nlohmann::json SummaryJson(const SiftOptions& options, const FeaturesStageStats& stats, nlohmann::json per_image) {
  const size_t n = stats.images;
  return {{"images", n},
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
          {"memory", MemoryJson(options, stats)},
          {"per_image", std::move(per_image)}};
}

// Fills the memory plan's part of the stats: the largest estimate, how many images fit at once, tiling.
void PlanStats(const std::vector<SiftMemoryPlan>& plans, double budget, FeaturesStageStats* stats) {
  for (const auto& p : plans) {
    stats->max_image_bytes = std::max(stats->max_image_bytes, p.estimated_bytes);
    stats->tiled_images += p.tiles.size() > 1;
    stats->max_tiles = std::max(stats->max_tiles, p.tiles.size());
  }
  const double fit = stats->max_image_bytes > 0 ? std::floor(budget / stats->max_image_bytes) : 1e9;
  const size_t threads = static_cast<size_t>(std::max(1, core::NumThreads()));
  stats->workers = std::min({threads, std::max<size_t>(1, plans.size()), static_cast<size_t>(std::max(fit, 1.0))});
}

}  // namespace

FeaturesStageStats RunFeaturesStage(const core::Workspace& ws, const SiftOptions& options, bool force) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  const fs::path frames_dir = ws.frames_dir(), features_dir = ws.features_dir();
  const auto index = io::ReadFramesIndex(ws.frames_json());
  core::EnsureDirectory(features_dir);
  const size_t n = index.frames.size();
  const double budget = options.max_memory_mb * 1048576.0;
  std::vector<ImageResult> results(n);
  std::vector<SiftMemoryPlan> plans(n);
  for (size_t i = 0; i < n; ++i) plans[i] = PlanFrame(index, index.frames[i], options, budget);
  FeaturesStageStats stats;
  PlanStats(plans, budget, &stats);
  MemoryGate gate(budget);

  // Parallelism is over images; OpenCV's own parallel_for inside SIFT would oversubscribe the cores. When the
  // budget lets one image in at a time (large photos), the images run in turn and OpenCV's threads work inside
  // each (its parallel parts: the difference of Gaussians, the extrema search, the descriptors).
  const int cv_threads = cv::getNumThreads();
  const bool one_at_a_time = stats.workers <= 1;
  cv::setNumThreads(one_at_a_time ? cv_threads : 1);
  core::Progress progress("features", n);
  // Every image and threshold rebuilds a scale space of the same sizes: its matrices are kept for the next.
  const io::ScopedMatrixReuse reuse;
  auto extract = [&](size_t i) {
    const auto& frame = index.frames[i];
    const fs::path image_path = frames_dir / frame.name, out_path = FeaturePath(features_dir, frame.name);
    ImageResult& r = results[i];
    r.threshold = options.contrast_threshold;
    try {
      if (!force && UpToDate(out_path, image_path)) {
        const FeatureSet done = ReadFeatures(out_path);
        r.keypoints = done.keypoints.size();
        if (done.contrast_threshold > 0) r.threshold = done.contrast_threshold;
        r.adapted = r.threshold < options.contrast_threshold;
        r.skipped = 1;
      } else {
        ExtractFrame(image_path, out_path, frame.name, options, budget, plans[i], &gate, &r);
      }
    } catch (const std::exception& e) {
      r.error = e.what();
    }
    progress.Add();
  };
  if (one_at_a_time) {
    for (size_t i = 0; i < n; ++i) extract(i);
  } else {
    tbb::parallel_for(size_t{0}, n, extract);
  }
  progress.Finish();
  cv::setNumThreads(cv_threads);
  for (const auto& r : results)
    if (!r.error.empty()) throw Error(r.error);

  stats.images = n;
  stats.peak_bytes_in_flight = gate.peak_bytes();
  stats.peak_images_in_flight = gate.peak_holders();
  stats.min_keypoints = n ? SIZE_MAX : 0;
  size_t num_skipped = 0;
  nlohmann::json per_image = nlohmann::json::array();
  for (size_t i = 0; i < n; ++i) {
    const ImageResult& r = results[i];
    stats.total_keypoints += r.keypoints;
    stats.min_keypoints = std::min(stats.min_keypoints, r.keypoints);
    stats.max_keypoints = std::max(stats.max_keypoints, r.keypoints);
    num_skipped += r.skipped;
    stats.adapted_images += r.adapted;
    per_image.push_back({{"name", index.frames[i].name}, {"keypoints", r.keypoints}});
    if (r.adapted) per_image.back()["contrast_threshold"] = r.threshold;
  }
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // How many images an interrupted earlier run had done is logged, not written: the summary describes the features,
  // which are the same whether or not the run was resumed.
  if (num_skipped > 0) spdlog::info("features: {} of {} images were up to date from an earlier run", num_skipped, n);
  core::WriteJson(features_dir / "features.json", SummaryJson(options, stats, std::move(per_image)));
  spdlog::info("features: {} images, {} keypoints (min {}, max {}), {:.1f} s{}", n, stats.total_keypoints,
               stats.min_keypoints, stats.max_keypoints, stats.seconds,
               stats.adapted_images
                   ? fmt::format("; contrast threshold lowered on {} weak images", stats.adapted_images)
                   : std::string());
  spdlog::info("features: memory budget {:.0f} MB, ≤ {:.0f} MB per image, {} at once (peak {}, {:.0f} MB){}",
               options.max_memory_mb, stats.max_image_bytes / 1048576.0, stats.workers, stats.peak_images_in_flight,
               stats.peak_bytes_in_flight / 1048576.0,
               stats.tiled_images ? fmt::format(", {} images in up to {} tiles", stats.tiled_images, stats.max_tiles)
                                  : std::string());
  return stats;
}

}  // namespace fmv3d::features
