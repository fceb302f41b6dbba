#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/ingest/keyframes.h"
#include "video_test_util.h"

namespace fmv3d::ingest {
namespace {

// A camera flying a circle over a textured ground, heading along the circle (a nadir orbit): the view
// translates and rotates. Pose of frame i: centre on the circle, heading angle.
struct Orbit {
  double radius = 320, cx = 700, cy = 700;
  int frames = 1800;  // 60 s at 30 fps, one full turn
  double Angle(int i) const { return 2 * M_PI * i / frames; }
  cv::Point2d Centre(int i) const { return {cx + radius * std::cos(Angle(i)), cy + radius * std::sin(Angle(i))}; }
  // Where texture point t appears in frame i (see ViewOf).
  cv::Point2d Image(int i, cv::Point2d t, cv::Size size) const {
    const double a = Angle(i), c = std::cos(a), s = std::sin(a);
    const cv::Point2d d = t - Centre(i);
    return {size.width / 2.0 + c * d.x + s * d.y, size.height / 2.0 - s * d.x + c * d.y};
  }
};

std::vector<Keyframe> RunSelector(KeyframeSelector& sel, int n, const std::function<cv::Mat(int)>& frame, double fps) {
  std::vector<Keyframe> kept;
  VideoFrame f;
  for (int i = 0; i < n; ++i) {
    f.image = frame(i);
    f.index = i;
    f.timestamp = i / fps;
    sel.Push(f, &kept);
  }
  sel.Finish(&kept);
  return kept;
}

TEST(Keyframes, OrbitSixtySecondsGivesDozensOfOverlappingKeyframes) {
  const cv::Mat tex = test::RandomTexture(1400, 1400, 11);
  const Orbit orbit;
  const cv::Size size(320, 240);
  KeyframeSelector sel(KeyframeOptions(), 30.0);
  const auto kept = RunSelector(
      sel, orbit.frames,
      [&](int i) { return test::ViewOf(tex, size, orbit.Centre(i).x, orbit.Centre(i).y, 1.0, orbit.Angle(i)); }, 30.0);
  RecordProperty("keyframes", static_cast<int>(kept.size()));
  std::printf("orbit 60 s @ 30 fps: %zu keyframes\n", kept.size());
  EXPECT_GE(kept.size(), 60u);
  EXPECT_LE(kept.size(), 150u);
  EXPECT_EQ(kept.front().index, 0);
  EXPECT_GE(kept.back().index, orbit.frames - sel.max_gap());
  // Overlap between consecutive keyframes from ground truth: where the centre of keyframe k lands in
  // keyframe k+1 — never outside the middle half of the image, and the spacing is driven by motion (not
  // just the max gap): some gaps shorter than the maximum.
  int short_gaps = 0;
  for (size_t k = 0; k + 1 < kept.size(); ++k) {
    const int a = static_cast<int>(kept[k].index);
    const int b = static_cast<int>(kept[k + 1].index);
    EXPECT_GE(b - a, sel.min_gap() - 1);  // the tail frame may be closer
    EXPECT_LE(b - a, sel.max_gap() + std::max(3, sel.min_gap()) + 1);
    const cv::Point2d moved = orbit.Image(b, orbit.Centre(a), size) - cv::Point2d(size.width / 2.0, size.height / 2.0);
    EXPECT_LT(std::hypot(moved.x, moved.y), 0.25 * size.width) << "keyframes " << a << " -> " << b;
    if (b - a < sel.max_gap()) ++short_gaps;
  }
  EXPECT_GT(short_gaps, static_cast<int>(kept.size()) / 2);
}

TEST(Keyframes, SpacingFollowsSpeed) {
  // First half pans slowly, second half four times faster: keyframes four times denser in the second half.
  const cv::Mat tex = test::RandomTexture(3200, 400, 12);
  const int n = 600;
  auto x = [&](int i) { return i < n / 2 ? 300 + 0.5 * i : 300 + 0.5 * n / 2 + 2.0 * (i - n / 2); };
  KeyframeOptions opt;
  opt.min_gap = 2;
  opt.max_gap = 100;
  KeyframeSelector sel(opt, 30.0);
  const auto kept = RunSelector(
      sel, n,
      [&](int i) {
        return test::ViewOf(tex, {320, 240}, x(i), 200);
      },
      30.0);
  int slow = 0, fast = 0;
  for (const auto& k : kept) (k.index < n / 2 ? slow : fast)++;
  EXPECT_GE(slow, 5);
  EXPECT_GT(fast, 3 * slow) << "slow half " << slow << ", fast half " << fast;
  // 5% of 320 px = 16 px: about 32 frames per keyframe slow, 8 fast.
  std::printf("slow half %d keyframes, fast half %d\n", slow, fast);
  EXPECT_NEAR(fast, 300 / 8, 10);
}

TEST(Keyframes, StaticSceneKeepsOnePerMaxGap) {
  const cv::Mat tex = test::RandomTexture(400, 300, 13);
  const cv::Mat view = test::ViewOf(tex, {320, 240}, 200, 150);
  KeyframeOptions opt;
  opt.max_gap = 25;
  KeyframeSelector sel(opt, 30.0);
  const auto kept = RunSelector(
      sel, 200, [&](int) { return view; }, 30.0);
  // 0, 25, ..., 175 = 8 frames, plus possibly the tail (frame 199).
  EXPECT_GE(kept.size(), 8u);
  EXPECT_LE(kept.size(), 9u);
  for (size_t k = 0; k < 8 && k < kept.size(); ++k) EXPECT_EQ(kept[k].index, static_cast<int64_t>(25 * k));
}

TEST(Keyframes, BlurredFramesAreNeverKept) {
  const cv::Mat tex = test::RandomTexture(2400, 400, 14);
  const int n = 300;
  std::set<int> blurred;
  for (int i = 5; i < n; i += 7) blurred.insert(i);
  for (int i = 100; i < 115; ++i) blurred.insert(i);  // a burst longer than the wait for a sharp frame
  KeyframeSelector sel(KeyframeOptions(), 30.0);
  const auto kept = RunSelector(
      sel, n,
      [&](int i) {
        cv::Mat v = test::ViewOf(tex, {320, 240}, 300 + 3.0 * i, 200);
        if (blurred.count(i)) cv::GaussianBlur(v, v, cv::Size(0, 0), 2.5);
        return v;
      },
      30.0);
  ASSERT_GT(kept.size(), 10u);
  int kept_blurred = 0;
  for (const auto& k : kept)
    if (blurred.count(static_cast<int>(k.index))) ++kept_blurred;
  // Inside the 15-frame burst one blurred frame may be taken (the best of the wait); elsewhere none.
  EXPECT_LE(kept_blurred, 1);
  for (const auto& k : kept)
    if (blurred.count(static_cast<int>(k.index))) {
      EXPECT_TRUE(k.index >= 100 && k.index < 115) << k.index;
    }
  // Every isolated blurred frame is detected; inside the burst the running median adapts (relative test).
  int isolated = 0;
  for (int i : blurred) isolated += (i < 100 || i >= 115) ? 1 : 0;
  EXPECT_GE(sel.blurred_frames(), isolated);
  EXPECT_LE(sel.blurred_frames(), static_cast<int64_t>(blurred.size()));
  // Sharp frames: a clear margin over the blurred ones.
  const double s_sharp = Sharpness(test::ViewOf(tex, {320, 240}, 400, 200));
  cv::Mat b;
  cv::GaussianBlur(test::ViewOf(tex, {320, 240}, 400, 200), b, cv::Size(0, 0), 2.5);
  EXPECT_GT(s_sharp, 3 * Sharpness(b));
}

TEST(Keyframes, AllFramesAndAutoGaps) {
  KeyframeOptions opt;
  opt.all_frames = true;
  KeyframeSelector sel(opt, 30.0);
  const cv::Mat tex = test::RandomTexture(400, 300, 15);
  const auto kept = RunSelector(
      sel, 20,
      [&](int i) {
        return test::ViewOf(tex, {160, 120}, 200 + i, 150);
      },
      30.0);
  EXPECT_EQ(kept.size(), 20u);
  // Auto gaps: 0.4 s and 1 s of video, at least one frame.
  KeyframeSelector one_fps(KeyframeOptions(), 1.0);
  EXPECT_EQ(one_fps.min_gap(), 1);
  EXPECT_EQ(one_fps.max_gap(), 1);
  KeyframeSelector thirty(KeyframeOptions(), 30.0);
  EXPECT_EQ(thirty.min_gap(), 12);
  EXPECT_EQ(thirty.max_gap(), 30);
  KeyframeOptions bad;
  bad.min_gap = 10;
  bad.max_gap = 5;
  EXPECT_THROW(bad.Check(), Error);
}

}  // namespace
}  // namespace fmv3d::ingest
