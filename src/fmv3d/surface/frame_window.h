// The frames texturing reads, held in a bounded window. Texturing reads the frames in two passes (visibility over
// all views, then seam colours and chart copies over the labelled ones); each pass needs one frame at a time,
// so frames are decoded on demand and the least recently used one is dropped when the window is full. A pass
// declares its order up front (Prefetch): the next frames are decoded in parallel, as many as fit, and passes
// alternate direction so that a pass starts on the frames the previous one ended with. Memory is then the
// window's frames (3 bytes per pixel) and not every registered frame's, whatever the number of frames.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <vector>

namespace fmv3d::surface {

// How many frames of `bytes_per_frame` fit `budget_mb`: at least 1, at most `frames` (all: nothing reloaded).
size_t ChooseFrameWindow(size_t frames, double bytes_per_frame, double budget_mb);

class FrameWindow {
 public:
  // `load(i)` gives frame i's pixels (it may throw); called from several threads at once by Prefetch.
  FrameWindow(size_t frames, std::function<cv::Mat(size_t)> load, size_t capacity);

  // Frame i, loaded when not held (the least recently used held frame is dropped when the window is full). The
  // returned header shares the pixels: a caller keeps a frame alive past its eviction only while it holds it.
  cv::Mat Get(size_t i);
  // Decodes, in parallel, those of the first capacity() frames of `order` that are not held, after dropping the
  // least recently used frames not among them to make room: the window never holds more than its capacity.
  void Prefetch(const std::vector<size_t>& order);
  // One pass: fn(i, pixels) for every frame of `frames` (each once), decoded in batches of capacity() frames
  // (Prefetch). In ascending order when `ascending`; otherwise against the previous pass's direction, so that it
  // starts on the frames the previous pass ended with (still held).
  void ForEach(std::vector<size_t> frames, const std::function<void(size_t, const cv::Mat&)>& fn,
               bool ascending = false);
  // Drops every frame.
  void Release() { resident_.clear(); }

  size_t frames() const { return frames_; }
  size_t capacity() const { return capacity_; }
  size_t loads() const { return loads_; }                  // frames decoded (> frames() when some were reloaded)
  size_t peak_resident() const { return peak_resident_; }  // most frames held at once
  size_t resident() const { return resident_.size(); }

 private:
  void Insert(size_t i, cv::Mat image);
  void EvictTo(size_t size, const std::vector<size_t>& keep);

  size_t frames_;
  std::function<cv::Mat(size_t)> load_;
  size_t capacity_;
  std::map<size_t, std::pair<uint64_t, cv::Mat>> resident_;  // frame → (last use, pixels)
  uint64_t clock_ = 0;
  bool last_descending_ = true;  // the first pass runs ascending
  size_t loads_ = 0, peak_resident_ = 0;
};

}  // namespace fmv3d::surface
