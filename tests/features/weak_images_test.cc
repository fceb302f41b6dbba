// Features that do not give up on weak images (adaptive contrast threshold, coverage), and kAuto's choice of
// GPS footprint pairs for photo surveys.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/features/sift.h"
#include "fmv3d/features/spatial_pairs.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::features {
namespace {

// Sand-like image: a smooth base with faint ripples and a few DN of grain; one textured corner patch (a bush)
// that a fixed threshold finds all its keypoints in.
cv::Mat FaintImage(int w, int h, uint64_t seed) {
  cv::Mat f(h, w, CV_32F);
  cv::RNG rng(seed);
  cv::Mat grain(h / 4, w / 4, CV_32F);
  rng.fill(grain, cv::RNG::NORMAL, 0, 0.8);
  cv::resize(grain, grain, cv::Size(w, h), 0, 0, cv::INTER_CUBIC);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      f.at<float>(y, x) = 170 + 0.8f * std::sin(0.09f * (0.8f * x + 0.6f * y)) + grain.at<float>(y, x);
  cv::Mat bush(h / 6, w / 6, CV_32F);
  rng.fill(bush, cv::RNG::UNIFORM, 60, 200);
  cv::GaussianBlur(bush, bush, cv::Size(0, 0), 1.5);
  bush.copyTo(f(cv::Rect(0, 0, w / 6, h / 6)));
  cv::Mat out;
  f.convertTo(out, CV_8U);
  return out;
}

TEST(WeakImages, CoverageCountsOccupiedCells) {
  std::vector<Keypoint> k = {{1, 1, 1, 0}, {2, 2, 1, 0}, {99, 99, 1, 0}};
  EXPECT_DOUBLE_EQ(KeypointCoverage(k, 100, 100, 2), 0.5);
  EXPECT_DOUBLE_EQ(KeypointCoverage({}, 100, 100, 4), 0.0);
  EXPECT_DOUBLE_EQ(KeypointCoverage(k, 0, 100, 4), 0.0);
}

TEST(WeakImages, AdaptiveThresholdFindsMoreAndBetterSpreadKeypoints) {
  const cv::Mat img = FaintImage(1200, 800, 4);
  SiftOptions fixed;
  fixed.min_features = 0;  // no adaptation
  SiftOptions adaptive;    // defaults: adapt below 2000 keypoints or half the grid covered
  double used_fixed = 0, used_adaptive = 0;
  const auto a = ExtractSift(img, fixed, &used_fixed);
  const auto b = ExtractSift(img, adaptive, &used_adaptive);
  const double ca = KeypointCoverage(a.keypoints, img.cols, img.rows),
               cb = KeypointCoverage(b.keypoints, img.cols, img.rows);
  std::printf("fixed: %zu keypoints, coverage %.2f; adaptive: %zu keypoints, coverage %.2f, threshold %.4f\n",
              a.keypoints.size(), ca, b.keypoints.size(), cb, used_adaptive);
  EXPECT_DOUBLE_EQ(used_fixed, fixed.contrast_threshold);
  EXPECT_LT(used_adaptive, adaptive.contrast_threshold);
  EXPECT_GE(used_adaptive, adaptive.min_contrast_threshold);
  EXPECT_GT(b.keypoints.size(), 2 * a.keypoints.size());
  EXPECT_GT(cb, ca + 0.2);
}

TEST(WeakImages, TexturedImageKeepsTheConfiguredThreshold) {
  cv::Mat img(600, 800, CV_8UC1);
  cv::RNG(7).fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(0, 0), 1.2);
  double used = 0;
  const auto f = ExtractSift(img, SiftOptions{}, &used);
  EXPECT_DOUBLE_EQ(used, SiftOptions{}.contrast_threshold);
  EXPECT_GE(static_cast<int>(f.keypoints.size()), SiftOptions{}.min_features);
}

TEST(WeakImages, BadAdaptationOptionsAreRejected) {
  SiftOptions o;
  o.min_coverage = 1.5;
  EXPECT_THROW(o.Check(), Error);
  o = SiftOptions{};
  o.min_contrast_threshold = 0;
  EXPECT_THROW(o.Check(), Error);
}

io::FramesIndex Photos(int n, bool gps_on_all, bool one_source) {
  io::FramesIndex index;
  io::CameraPrior cam;
  cam.camera = core::Camera::Pinhole(800, 450, 700);
  index.cameras.push_back(cam);
  for (int k = 0; k < n; ++k) {
    io::FrameRecord f;
    f.name = "p" + std::to_string(k) + ".jpg";
    f.source = one_source ? "clip.mp4" : "/in/p" + std::to_string(k) + ".jpg";
    if (gps_on_all || k != 3)
      f.telemetry = core::TelemetryFromJson({{"time", 0.0},
                                             {"sensor_latitude", 47.0 + 1e-5 * (k % 10)},
                                             {"sensor_longitude", 8.0 + 1e-5 * std::floor(k / 10.0)},
                                             {"sensor_relative_altitude", 80.0}});
    index.frames.push_back(f);
  }
  return index;
}

TEST(WeakImages, AutoPairsUseGpsFootprintsForLargePhotoSurveys) {
  PairOptions o;  // exhaustive up to 50 images
  const auto big = Photos(60, true, false);
  EXPECT_TRUE(PreferSpatialPairs(big, FootprintsFromTelemetry(big), o));
  const auto small = Photos(20, true, false);
  EXPECT_FALSE(PreferSpatialPairs(small, FootprintsFromTelemetry(small), o));  // exhaustive is affordable
  const auto gap = Photos(60, false, false);
  EXPECT_FALSE(PreferSpatialPairs(gap, FootprintsFromTelemetry(gap), o));  // one photo without GPS
  const auto video = Photos(60, true, true);
  EXPECT_FALSE(PreferSpatialPairs(video, FootprintsFromTelemetry(video), o));  // frames of one video
}

}  // namespace
}  // namespace fmv3d::features
