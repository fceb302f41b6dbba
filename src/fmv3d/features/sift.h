// SIFT keypoints + descriptors (OpenCV's SIFT) and the `fmv3d features` stage.
//
// OpenCV's default contrast threshold (0.04) keeps several times fewer keypoints than COLMAP/VLFeat on the same
// frames: OpenCV's final test is |D| < contrast_threshold / n_octave_layers, VLFeat's (COLMAP's peak_threshold
// 0.02 / 3 octave layers) is half of that. Our default 0.01 is looser still, so textured 720p frames give
// thousands of keypoints; the per-image cap then keeps the strongest responses.
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/workspace.h"
#include "fmv3d/features/sift_memory.h"
#include "fmv3d/features/types.h"

namespace fmv3d::features {

struct SiftOptions {
  int max_features = 8000;    // per image; the strongest responses are kept (0 = no cap)
  int max_image_size = 3200;  // larger images are downscaled for extraction; coordinates are rescaled
  double contrast_threshold = 0.01;
  double edge_threshold = 10;
  int octave_layers = 3;
  bool root_sift = true;  // RootSIFT (L1-normalise, sqrt): better matching under Euclidean distance
  bool upright = false;   // one orientation (0) per keypoint: for nadir / no-roll imagery
  // Weak images (sand, water, fields, snow): when fewer than min_features keypoints are found, or they cover
  // less than min_coverage of a 16 x 16 grid over the image, the contrast threshold is halved and detection
  // repeated, down to min_contrast_threshold. 0 disables the adaptation.
  int min_features = 2000;
  double min_coverage = 0.5;
  double min_contrast_threshold = 0.0012;
  // The stage's budget (`--max-memory`): images run in parallel only while their estimated SIFT working sets fit
  // it, and an image whose own working set exceeds it is extracted in tiles (sift_memory.h).
  double max_memory_mb = 2048;
  void Check() const;
};

// Share of the cells of a grid x grid partition of a width x height image that hold at least one keypoint.
double KeypointCoverage(const std::vector<Keypoint>& keypoints, int width, int height, int grid = 16);

// Extracts from an 8-bit image (grey or BGR as cv::imread gives). Keypoints in fmv3d pixels (centres at +0.5) of
// the full-size image. Colours are sampled from the image (grey replicated). Deterministic. Single-threaded
// in OpenCV when called from the stage (parallelism is over images).
// The contrast threshold finally used goes to `contrast_threshold_used` when given.
// With more than one tile (PlanSiftTiles over the extraction image, i.e. after the max_image_size downscale), SIFT
// runs on each tile's window and keeps the keypoints in its core; the contrast adaptation and the max_features cap
// then apply to the whole image's keypoints as without tiles. With no tile or one, the image is extracted whole.
FeatureSet ExtractSift(const cv::Mat& image, const SiftOptions& options, double* contrast_threshold_used = nullptr,
                       const std::vector<SiftTile>& tiles = {});

// Quantises a float SIFT descriptor row (OpenCV scale, ~0..255) to uint8 as COLMAP does: L2 (or RootSIFT)
// normalised, times 512, clamped.
void QuantiseDescriptors(const cv::Mat& descriptors_f32, bool root_sift, Descriptors* out);

// Upright SIFT descriptors (orientation 0) at given points of an 8-bit image (fmv3d pixels, full size), each at
// its keypoint's scale (fmv3d scale: keypoint size / 2); for keypoints the operator places by hand
// (features/manual_matches.h). Row i belongs to keypoints[i].
Descriptors DescribeAt(const cv::Mat& image, const std::vector<Keypoint>& keypoints, bool root_sift = true);

struct FeaturesStageStats {
  size_t images = 0, total_keypoints = 0, min_keypoints = 0, max_keypoints = 0;
  size_t adapted_images = 0;  // images whose contrast threshold was lowered
  double seconds = 0;
  // Memory (sift_memory.h): the largest per-image estimate, how many images fit the budget at once, and what ran.
  double max_image_bytes = 0, peak_bytes_in_flight = 0;
  size_t workers = 0, peak_images_in_flight = 0, tiled_images = 0, max_tiles = 0;
};

// The `fmv3d features` stage: reads WS/frames/frames.json, writes WS/features/<stem>.feat for every frame
// (parallel over images), and WS/features/features.json (counts, timing). Skips frames whose .feat is newer
// than the image unless `force`. Images run in parallel within options.max_memory_mb (sift_memory.h); the
// summary's `memory` block reports the plan. Throws fmv3d::Error for a missing workspace or an unreadable image.
FeaturesStageStats RunFeaturesStage(const core::Workspace& workspace, const SiftOptions& options, bool force = false);

}  // namespace fmv3d::features
