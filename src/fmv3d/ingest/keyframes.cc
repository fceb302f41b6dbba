#include "fmv3d/ingest/keyframes.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"

namespace fmv3d::ingest {
namespace {

cv::Mat ToGrey(const cv::Mat& img) {
  if (img.channels() == 1) return img;
  cv::Mat g;
  cv::cvtColor(img, g, img.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return g;
}

cv::Mat Downscale(const cv::Mat& grey, int max_side) {
  const int side = std::max(grey.cols, grey.rows);
  if (side <= max_side) return grey;
  const double s = static_cast<double>(max_side) / side;
  cv::Mat out;
  cv::resize(grey, out,
             cv::Size(std::max(1, int(std::lround(grey.cols * s))), std::max(1, int(std::lround(grey.rows * s)))), 0, 0,
             cv::INTER_AREA);
  return out;
}

using core::Median;

// KLT: frame-to-frame motion at the working scale (<= 480 px) is a few pixels, so a 15 px window on a
// 3-level pyramid is ample and costs half of OpenCV's default 21 px window.
const cv::Size kWin(15, 15);
constexpr int kLevels = 2;

}  // namespace

void KeyframeOptions::Check() const {
  if (min_gap < 0 || max_gap < 0) throw Error("keyframes: --min-gap and --max-gap must be >= 0");
  if (max_gap > 0 && min_gap > max_gap) throw Error("keyframes: --min-gap must not exceed --max-gap");
  if (!(min_motion > 0 && min_motion < 1)) throw Error("keyframes: min_motion must be in (0, 1)");
  if (!(min_overlap >= 0 && min_overlap <= 1)) throw Error("keyframes: min_overlap must be in [0, 1]");
  if (!(blur_ratio >= 0 && blur_ratio < 1)) throw Error("keyframes: blur_ratio must be in [0, 1)");
  if (blur_window < 1 || track_size < 32 || max_features < 8) throw Error("keyframes: bad tracking options");
}

double Sharpness(const cv::Mat& image) {
  if (image.empty()) return 0;
  const cv::Mat g = Downscale(ToGrey(image), 960);
  cv::Mat lap;
  cv::Laplacian(g, lap, CV_32F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(lap, mean, stddev);
  return stddev[0] * stddev[0];
}

KeyframeSelector::KeyframeSelector(const KeyframeOptions& options, double fps) : options_(options) {
  options_.Check();
  if (!(fps > 0 && fps < 1000)) fps = 30;
  min_gap_ = options_.min_gap > 0 ? options_.min_gap : std::max(1, int(std::lround(0.4 * fps)));
  max_gap_ = options_.max_gap > 0 ? options_.max_gap : std::max(min_gap_, int(std::lround(1.0 * fps)));
  if (options_.max_gap == 0 && max_gap_ < min_gap_) max_gap_ = min_gap_;
  if (min_gap_ > max_gap_) min_gap_ = max_gap_;
}

void KeyframeSelector::ResetTracks() {
  key_pts_.clear();
  const int side = std::max(work_.cols, work_.rows);
  cv::goodFeaturesToTrack(work_, key_pts_, options_.max_features, 0.01, std::max(3.0, side / 40.0));
  pts_ = key_pts_;
  initial_tracks_ = key_pts_.size();
}

void KeyframeSelector::Keep(const cv::Mat& image, int64_t index, double timestamp, double sharpness,
                            std::vector<Keyframe>* out) {
  Keyframe k;
  k.image = image.clone();
  k.index = index;
  k.timestamp = timestamp;
  k.sharpness = sharpness;
  out->push_back(std::move(k));
  has_key_ = true;
  last_key_index_ = index;
  pending_ = false;
  pending_count_ = 0;
  best_pending_ = Keyframe();
  best_pending_score_ = -1;
  has_tail_ = false;
  // Tracks restart from the newest image we have (the current frame), even if a buffered older frame was
  // kept: the displacement since then is at most a few frames and only delays the next keyframe slightly.
  ResetTracks();
}

void KeyframeSelector::Push(const VideoFrame& frame, std::vector<Keyframe>* out) {
  ++frames_seen_;
  const cv::Mat grey = ToGrey(frame.image);
  const double sharpness = Sharpness(grey);
  std::swap(prev_work_, work_);
  std::swap(prev_pyr_, pyr_);
  work_ = Downscale(grey, options_.track_size).clone();
  // Pyramids are built once per frame and reused as the "previous" one for the next frame.
  if (!options_.all_frames) cv::buildOpticalFlowPyramid(work_, pyr_, kWin, kLevels);

  if (options_.all_frames) {
    Keyframe k{frame.image.clone(), frame.index, frame.timestamp, sharpness};
    out->push_back(std::move(k));
    return;
  }

  // Relative blur test against the previous frames' median.
  double median = 0;
  if (!sharpness_history_.empty()) median = Median(sharpness_history_);
  const bool blurred = sharpness_history_.size() >= 3 && sharpness < options_.blur_ratio * median;
  const double score = median > 0 ? sharpness / median : 1;
  if (static_cast<int>(sharpness_history_.size()) < options_.blur_window) {
    sharpness_history_.push_back(sharpness);
  } else {
    sharpness_history_[history_pos_] = sharpness;
    history_pos_ = (history_pos_ + 1) % sharpness_history_.size();
  }
  if (blurred) ++blurred_;

  // Track the keyframe's corners into this frame.
  double displacement = 0, survival = 1;
  if (has_key_ && !pts_.empty() && prev_work_.size() == work_.size()) {
    std::vector<cv::Point2f> next, back;
    std::vector<uchar> st, st_back;
    std::vector<float> err;
    const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
    cv::calcOpticalFlowPyrLK(prev_pyr_, pyr_, pts_, next, st, err, kWin, kLevels, term);
    cv::calcOpticalFlowPyrLK(pyr_, prev_pyr_, next, back, st_back, err, kWin, kLevels, term);
    size_t n = 0;
    for (size_t i = 0; i < pts_.size(); ++i) {
      const bool inside = next[i].x >= 0 && next[i].y >= 0 && next[i].x < work_.cols && next[i].y < work_.rows;
      const double fb = std::hypot(back[i].x - pts_[i].x, back[i].y - pts_[i].y);
      if (st[i] && st_back[i] && inside && fb < 1.0) {
        pts_[n] = next[i];
        key_pts_[n] = key_pts_[i];
        ++n;
      }
    }
    pts_.resize(n);
    key_pts_.resize(n);
  } else if (has_key_) {
    pts_.clear();
    key_pts_.clear();
  }
  if (has_key_) {
    if (initial_tracks_ > 0) survival = static_cast<double>(pts_.size()) / initial_tracks_;
    std::vector<double> d(pts_.size());
    for (size_t i = 0; i < pts_.size(); ++i) d[i] = std::hypot(pts_[i].x - key_pts_[i].x, pts_[i].y - key_pts_[i].y);
    displacement = d.empty() ? 0 : Median(d) / std::max(work_.cols, work_.rows);
  }

  const int64_t gap = has_key_ ? frame.index - last_key_index_ : 0;
  const bool moved = displacement >= options_.min_motion || (initial_tracks_ > 0 && survival < options_.min_overlap);
  const bool due = !has_key_ || gap >= max_gap_ || (gap >= min_gap_ && moved);
  if (due || pending_) {
    if (!blurred) {
      Keep(frame.image, frame.index, frame.timestamp, sharpness, out);
      return;
    }
    pending_ = true;
    ++pending_count_;
    if (score > best_pending_score_) {
      best_pending_score_ = score;
      frame.image.copyTo(best_pending_.image);
      best_pending_.index = frame.index;
      best_pending_.timestamp = frame.timestamp;
      best_pending_.sharpness = sharpness;
    }
    // Wait at most min_gap frames (a few at least) for a sharp one, then take the best seen.
    if (pending_count_ > std::max(3, min_gap_)) {
      const Keyframe best = best_pending_;
      Keep(best.image, best.index, best.timestamp, best.sharpness, out);
    }
    return;
  }
  if (!blurred && gap >= min_gap_) {
    frame.image.copyTo(tail_.image);
    tail_.index = frame.index;
    tail_.timestamp = frame.timestamp;
    tail_.sharpness = sharpness;
    has_tail_ = true;
  }
}

void KeyframeSelector::Finish(std::vector<Keyframe>* out) {
  if (pending_ && best_pending_score_ >= 0) {
    out->push_back(best_pending_);
  } else if (has_tail_) {
    out->push_back(tail_);
  }
  pending_ = false;
  has_tail_ = false;
}

}  // namespace fmv3d::ingest
