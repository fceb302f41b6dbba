// The texture stage's frame window: never more frames held than its capacity (checked at every decode, from the
// loader), least recently used frames dropped first, every frame of a pass visited once, and passes alternating
// direction so that a pass starts on the frames the previous one left in the window.
#include "fmv3d/surface/frame_window.h"

#include <gtest/gtest.h>

#include <atomic>
#include <mutex>

#include "fmv3d/core/error.h"

namespace fmv3d::surface {
namespace {

// A loader of 4x2 frames filled with their index, recording each decode and checking the window's bound
// (frames held + decodes in flight ≤ capacity) at every one.
struct CountingLoader {
  FrameWindow* window = nullptr;
  std::atomic<int> in_flight{0};
  std::atomic<bool> over_bound{false};
  std::mutex mutex;
  std::vector<size_t> decoded;
  cv::Mat operator()(size_t i) {
    const int n = ++in_flight;
    if (window->resident() + n > window->capacity()) over_bound = true;
    {
      std::lock_guard<std::mutex> lock(mutex);
      decoded.push_back(i);
    }
    cv::Mat m(2, 4, CV_8UC3, cv::Scalar::all(static_cast<double>(i)));
    --in_flight;
    return m;
  }
};

struct Fixture {
  CountingLoader loader;
  FrameWindow window;
  Fixture(size_t frames, size_t capacity)
      : window(
            frames, [this](size_t i) { return loader(i); }, capacity) {
    loader.window = &window;
  }
};

TEST(FrameWindow, CapacityFromTheBudget) {
  EXPECT_EQ(ChooseFrameWindow(100, 1048576, 10), 10u);
  EXPECT_EQ(ChooseFrameWindow(100, 1048576, 10.9), 10u);
  EXPECT_EQ(ChooseFrameWindow(100, 1048576, 0.5), 1u);  // at least one frame
  EXPECT_EQ(ChooseFrameWindow(8, 1048576, 2048), 8u);   // at most all of them
  EXPECT_THROW(ChooseFrameWindow(8, 1048576, 0), Error);
  EXPECT_THROW(ChooseFrameWindow(8, 0, 10), Error);
}

TEST(FrameWindow, DropsTheLeastRecentlyUsedFrame) {
  Fixture fx(5, 2);
  EXPECT_EQ(fx.window.Get(0).at<cv::Vec3b>(0, 0)[0], 0);
  fx.window.Get(1);
  fx.window.Get(0);  // 1 is now the least recently used
  fx.window.Get(2);  // drops 1
  EXPECT_EQ(fx.window.resident(), 2u);
  fx.window.Get(0);  // still held: no decode
  EXPECT_EQ(fx.loader.decoded, (std::vector<size_t>{0, 1, 2}));
  EXPECT_EQ(fx.window.Get(1).at<cv::Vec3b>(1, 3)[2], 1);  // decoded again, in place of 2
  EXPECT_EQ(fx.loader.decoded.back(), 1u);
  fx.window.Get(0);
  EXPECT_EQ(fx.window.loads(), 4u);
  EXPECT_EQ(fx.window.peak_resident(), 2u);
  EXPECT_FALSE(fx.loader.over_bound);
  EXPECT_THROW(fx.window.Get(5), Error);
}

TEST(FrameWindow, PassesVisitEveryFrameOnceWithinTheBound) {
  // Decodes of three passes (all 20 frames ascending, then the 10 odd ones twice) by capacity: the first pass
  // decodes every frame, each later pass only those that left the window (worked out by hand from the LRU order:
  // e.g. capacity 7 ends pass 1 holding 13..19, pass 2 reuses 19, 17, 15, 13 and ends holding 1..13).
  const std::pair<size_t, size_t> expected_loads[] = {{1, 38}, {3, 35}, {7, 29}, {20, 20}};
  for (const auto& [capacity, loads] : expected_loads) {
    Fixture fx(20, capacity);
    std::vector<size_t> all, odd;
    for (size_t i = 0; i < 20; ++i) {
      all.push_back(i);
      if (i % 2) odd.push_back(i);
    }
    std::vector<size_t> seen[3];
    const auto visit = [&](int pass) {
      return [&, pass](size_t i, const cv::Mat& image) {
        EXPECT_EQ(image.at<cv::Vec3b>(0, 0)[0], i);
        seen[pass].push_back(i);
      };
    };
    fx.window.ForEach(all, visit(0), /*ascending=*/true);
    fx.window.ForEach(odd, visit(1));
    fx.window.ForEach(odd, visit(2));
    EXPECT_EQ(seen[0], all) << "capacity " << capacity;
    EXPECT_EQ(seen[1], std::vector<size_t>(odd.rbegin(), odd.rend()));  // back from where the first pass ended
    EXPECT_EQ(seen[2], odd);
    EXPECT_FALSE(fx.loader.over_bound) << "capacity " << capacity;
    EXPECT_LE(fx.window.peak_resident(), capacity);
    EXPECT_EQ(fx.window.loads(), loads) << "capacity " << capacity;
  }
}

TEST(FrameWindow, LoaderErrorsReachTheCaller) {
  FrameWindow window(
      4, [](size_t i) -> cv::Mat { throw Error("frame " + std::to_string(i) + ": unreadable"); }, 2);
  EXPECT_THROW(window.ForEach({0, 1, 2, 3}, [](size_t, const cv::Mat&) {}), Error);
  EXPECT_THROW(window.Get(3), Error);
}

}  // namespace
}  // namespace fmv3d::surface
