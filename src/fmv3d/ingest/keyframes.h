// Keyframe selection for video, streaming: frames are pushed one at a time and only a few are held (the
// previous grey working image, at most one buffered candidate and the last sharp frame), so any length of
// video runs in constant memory.
//
// 1. Sharpness = variance of the Laplacian of the grey frame (downscaled to <= 960 px). A frame is "blurred"
//    when its sharpness is below blur_ratio × the median of the previous blur_window frames (relative to its
//    neighbours, so a soft but steady camera is not rejected wholesale).
// 2. Motion: corners detected in the last keyframe (Shi–Tomasi) are tracked frame to frame with pyramidal
//    KLT on a downscaled grey image (forward–backward checked). A keyframe is due when the median displacement
//    of the surviving tracks since the keyframe reaches min_motion × image size, or when fewer than
//    min_overlap of the keyframe's tracks survive (the view has changed), but not before min_gap frames;
//    and always after max_gap frames.
// 3. A due frame that is blurred is not kept; the next sharp frame is, or after a short wait the sharpest
//    of the waiting frames.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/ingest/video_reader.h"

namespace fmv3d::ingest {

struct KeyframeOptions {
  int min_gap = 0;           // frames; 0 = auto: 0.4 s of video (at least 1)
  int max_gap = 0;           // frames; 0 = auto: 1 s of video (at least min_gap)
  double min_motion = 0.05;  // median track displacement, as a fraction of the image's larger side
  double min_overlap = 0.6;  // fraction of the keyframe's tracks still alive
  double blur_ratio = 0.6;   // blurred when sharpness < blur_ratio × running median
  int blur_window = 15;      // frames in the running median
  int track_size = 480;      // larger side of the KLT working image, pixels
  int max_features = 120;
  bool all_frames = false;  // keep every decoded frame (no selection, no blur rejection)
  // Throws fmv3d::Error on nonsensical values.
  void Check() const;
};

struct Keyframe {
  cv::Mat image;  // BGR, owned (a copy)
  int64_t index = 0;
  double timestamp = 0;
  double sharpness = 0;
};

// Variance of the Laplacian of the grey image, after downscaling so that the larger side is <= 960 px.
double Sharpness(const cv::Mat& bgr_or_grey);

class KeyframeSelector {
 public:
  // fps sets the automatic gaps (use 0 when unknown: then 30 is assumed).
  KeyframeSelector(const KeyframeOptions& options, double fps);
  // Feeds the next frame (in order); appends the frames selected now to *out (usually 0 or 1).
  void Push(const VideoFrame& frame, std::vector<Keyframe>* out);
  // End of the stream: appends a buffered candidate or the last sharp frame if the tail is uncovered.
  void Finish(std::vector<Keyframe>* out);

  int min_gap() const { return min_gap_; }
  int max_gap() const { return max_gap_; }
  int64_t frames_seen() const { return frames_seen_; }
  int64_t blurred_frames() const { return blurred_; }

 private:
  void Keep(const cv::Mat& image, int64_t index, double timestamp, double sharpness, std::vector<Keyframe>* out);
  void ResetTracks();

  KeyframeOptions options_;
  int min_gap_ = 1, max_gap_ = 30;
  int64_t frames_seen_ = 0, blurred_ = 0;
  std::vector<double> sharpness_history_;  // ring of the last blur_window values
  size_t history_pos_ = 0;

  cv::Mat work_, prev_work_;             // grey working images (current, previous)
  std::vector<cv::Mat> pyr_, prev_pyr_;  // their KLT pyramids
  std::vector<cv::Point2f> key_pts_, pts_;
  size_t initial_tracks_ = 0;
  bool has_key_ = false;
  int64_t last_key_index_ = -1;

  // Due but blurred: the best candidate so far.
  bool pending_ = false;
  int pending_count_ = 0;
  Keyframe best_pending_;
  double best_pending_score_ = -1;
  // The last sharp frame past min_gap, to close the tail of the video.
  Keyframe tail_;
  bool has_tail_ = false;
};

}  // namespace fmv3d::ingest
