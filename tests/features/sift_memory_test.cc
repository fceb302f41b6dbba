// The features stage's memory bound (features/sift_memory.h): the admission of images by their estimated working
// set, the tiling of an image too large for the budget, and tiled SIFT's agreement with whole-image SIFT.
#include "fmv3d/features/sift_memory.h"

#include <gtest/gtest.h>

#include <atomic>
#include <iostream>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>
#include <thread>
#include <tuple>

#include "fmv3d/features/feature_compare.h"
#include "fmv3d/features/sift.h"

namespace fmv3d::features {
namespace {

TEST(SiftMemory, AdmitsWhileTheEstimatesFitAndAlwaysOneImage) {
  EXPECT_TRUE(Admits(0, 0, 5e9, 1e9));  // alone: admitted even above the budget
  EXPECT_TRUE(Admits(4e8, 1, 6e8, 1e9));
  EXPECT_FALSE(Admits(4e8, 1, 6.1e8, 1e9));
  EXPECT_FALSE(Admits(1, 1, 5e9, 1e9));
}

// Threads acquiring random amounts (some above the budget): the bytes in flight never exceed the budget unless one
// image runs alone, and every request is served.
TEST(SiftMemory, GateNeverHoldsMoreThanTheBudget) {
  const double budget = 1000;
  MemoryGate gate(budget);
  std::atomic<int> holders{0}, served{0}, violations{0};
  std::atomic<long long> in_flight{0};
  std::vector<std::thread> threads;
  threads.reserve(6);
  for (int t = 0; t < 6; ++t)
    threads.emplace_back([&, t] {
      std::mt19937 rng(t);
      std::uniform_int_distribution<int> size(50, 1300);
      for (int k = 0; k < 200; ++k) {
        const int bytes = size(rng);
        gate.Acquire(bytes);
        const long long now = in_flight += bytes;
        const int h = ++holders;
        if (h > 1 && now > budget) ++violations;
        std::this_thread::yield();
        in_flight -= bytes;
        --holders;
        gate.Release(bytes);
        ++served;
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(violations.load(), 0);
  EXPECT_EQ(served.load(), 6 * 200);
  EXPECT_GE(gate.peak_holders(), 1u);
}

// Every pixel of the image in exactly one core; windows hold their cores, start on the alignment grid and fit.
void ExpectPartition(const std::vector<SiftTile>& tiles, int w, int h, const TilingLimits& limits) {
  std::vector<int> hits(static_cast<size_t>(w) * h, 0);
  for (const auto& t : tiles) {
    EXPECT_LE(t.window.x, t.core.x);
    EXPECT_LE(t.window.y, t.core.y);
    EXPECT_GE(t.window.x + t.window.width, t.core.x + t.core.width);
    EXPECT_GE(t.window.y + t.window.height, t.core.y + t.core.height);
    EXPECT_EQ(t.window.x % limits.align, 0);
    EXPECT_EQ(t.window.y % limits.align, 0);
    EXPECT_GE(t.window.x, 0);
    EXPECT_LE(t.window.x + t.window.width, w);
    for (int y = t.core.y; y < t.core.y + t.core.height; ++y)
      for (int x = t.core.x; x < t.core.x + t.core.width; ++x) ++hits[static_cast<size_t>(y) * w + x];
  }
  EXPECT_EQ(std::count(hits.begin(), hits.end(), 1), static_cast<long>(hits.size()));
}

TEST(SiftMemory, TilesPartitionTheImageAndFitTheBudget) {
  const TilingLimits limits;
  const int w = 3200, h = 2400;
  bool fits = false;
  const auto whole = PlanSiftTiles(w, h, SiftWindowBytes(static_cast<long long>(w) * h) + 10, 10, limits, &fits);
  ASSERT_EQ(whole.size(), 1u);
  EXPECT_TRUE(fits);
  EXPECT_EQ(whole[0].window, (PixelRect{0, 0, w, h}));
  for (double mb : {1024.0, 512.0, 256.0}) {
    const double budget = mb * 1048576;
    const auto tiles = PlanSiftTiles(w, h, budget, 0, limits, &fits);
    EXPECT_TRUE(fits) << mb;
    EXPECT_GT(tiles.size(), 1u) << mb;
    for (const auto& t : tiles) EXPECT_LE(SiftWindowBytes(t.window.area()), budget) << mb;
    ExpectPartition(tiles, w, h, limits);
  }
  // Nothing fits 1 MB: the finest tiling, flagged.
  const auto finest = PlanSiftTiles(w, h, 1048576, 0, limits, &fits);
  EXPECT_FALSE(fits);
  EXPECT_EQ(finest.size(), static_cast<size_t>((w / limits.min_core) * (h / limits.min_core)));
  ExpectPartition(finest, w, h, limits);
}

TEST(SiftMemory, TwelveMegapixelsWholeAtTheDefaultBudgetTiledBelow) {
  SiftOptions o;
  const auto whole = PlanSiftMemory(4000, 3000, o, o.max_memory_mb * 1048576);
  EXPECT_EQ(whole.extraction_width, 3200);
  EXPECT_EQ(whole.extraction_height, 2400);
  EXPECT_EQ(whole.tiles.size(), 1u);
  EXPECT_LE(whole.estimated_bytes, o.max_memory_mb * 1048576);
  const auto tiled = PlanSiftMemory(4000, 3000, o, 512 * 1048576.0);
  EXPECT_GT(tiled.tiles.size(), 1u);
  EXPECT_TRUE(tiled.fits);
  EXPECT_LE(tiled.estimated_bytes, 512 * 1048576.0);
  // 960x540 video: whole, and many at once within the default budget.
  EXPECT_EQ(PlanSiftMemory(960, 540, o, o.max_memory_mb * 1048576).tiles.size(), 1u);
  EXPECT_LT(PlanSiftMemory(960, 540, o, o.max_memory_mb * 1048576).estimated_bytes, 0.1 * o.max_memory_mb * 1048576);
}

cv::Mat TexturedImage(int w, int h) {
  cv::RNG rng(7);
  cv::Mat img(h, w, CV_8UC3);
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(0, 0), 2.0);
  cv::normalize(img, img, 0, 255, cv::NORM_MINMAX);
  for (int k = 0; k < 400; ++k)
    cv::circle(img, {rng.uniform(0, w), rng.uniform(0, h)}, rng.uniform(3, 40),
               cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255)), cv::FILLED);
  return img;
}

// Tiled SIFT on a 1600x1200 image: no keypoint twice, keypoints from every tile's core, and the keypoints of the
// whole-image extraction found again (bench/results/feat11.md has the 12 MP figures).
TEST(SiftMemory, TiledSiftAgreesWithWholeImage) {
  const cv::Mat img = TexturedImage(1600, 1200);
  SiftOptions o;
  o.max_features = 4000;
  const TilingLimits limits;
  const auto tiles = PlanSiftTiles(1600, 1200, SiftWindowBytes(1600LL * 1200) / 2.5, 0, limits);
  ASSERT_GE(tiles.size(), 4u);
  const FeatureSet whole = ExtractSift(img, o);
  const FeatureSet tiled = ExtractSift(img, o, nullptr, tiles);
  ASSERT_EQ(tiled.keypoints.size(), static_cast<size_t>(tiled.descriptors.rows()));
  std::set<std::tuple<float, float, float, float>> seen;
  std::vector<int> per_tile(tiles.size(), 0);
  for (const auto& k : tiled.keypoints) {
    EXPECT_TRUE(seen.insert({k.x, k.y, k.scale, k.orientation}).second) << "duplicate at " << k.x << ", " << k.y;
    for (size_t t = 0; t < tiles.size(); ++t) {
      const auto& c = tiles[t].core;  // OpenCV's pixel = ours − 0.25 (ExtractSift), no downscale here
      if (k.x - 0.25 >= c.x && k.x - 0.25 < c.x + c.width && k.y - 0.25 >= c.y && k.y - 0.25 < c.y + c.height)
        ++per_tile[t];
    }
  }
  for (size_t t = 0; t < tiles.size(); ++t) EXPECT_GT(per_tile[t], 50) << "tile " << t;
  const KeypointAgreement a = CompareKeypoints(whole, tiled);
  std::cout << whole.keypoints.size() << " / " << tiled.keypoints.size() << " keypoints in " << tiles.size()
            << " tiles: identical " << a.identical_share() << ", within 0.01 px " << a.within_share()
            << ", descriptor distance " << a.mean_descriptor_distance << "\n";
  EXPECT_GE(a.within_share(), 0.99);
  EXPECT_GE(a.identical_share(), 0.75);
  EXPECT_NEAR(double(tiled.keypoints.size()), double(whole.keypoints.size()), 0.05 * whole.keypoints.size());
}

}  // namespace
}  // namespace fmv3d::features
