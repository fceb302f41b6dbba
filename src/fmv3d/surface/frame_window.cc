#include "fmv3d/surface/frame_window.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::surface {

size_t ChooseFrameWindow(size_t frames, double bytes_per_frame, double budget_mb) {
  if (!(budget_mb > 0)) throw Error("texture: the memory budget must be > 0 MB");
  if (!(bytes_per_frame > 0)) throw Error("texture: a frame's size must be > 0 bytes");
  const double fit = std::floor(budget_mb * 1048576.0 / bytes_per_frame);
  const size_t fitting = fit >= static_cast<double>(frames) ? frames : static_cast<size_t>(std::max(fit, 0.0));
  return std::min(frames, std::max(fitting, size_t{1}));
}

FrameWindow::FrameWindow(size_t frames, std::function<cv::Mat(size_t)> load, size_t capacity)
    : frames_(frames), load_(std::move(load)), capacity_(std::max<size_t>(capacity, 1)) {}

void FrameWindow::Insert(size_t i, cv::Mat image) {
  ++loads_;
  resident_[i] = {++clock_, std::move(image)};
  peak_resident_ = std::max(peak_resident_, resident_.size());
}

// Drops least recently used frames, except those in `keep`, until at most `size` are held.
void FrameWindow::EvictTo(size_t size, const std::vector<size_t>& keep) {
  while (resident_.size() > size) {
    auto victim = resident_.end();
    for (auto it = resident_.begin(); it != resident_.end(); ++it)
      if (std::find(keep.begin(), keep.end(), it->first) == keep.end() &&
          (victim == resident_.end() || it->second.first < victim->second.first))
        victim = it;
    if (victim == resident_.end()) return;
    resident_.erase(victim);
  }
}

cv::Mat FrameWindow::Get(size_t i) {
  if (i >= frames_) throw Error("texture: frame " + std::to_string(i) + " is not among the views");
  auto it = resident_.find(i);
  if (it == resident_.end()) {
    EvictTo(capacity_ - 1, {});
    cv::Mat image = load_(i);
    Insert(i, image);
    return image;
  }
  it->second.first = ++clock_;
  return it->second.second;
}

void FrameWindow::Prefetch(const std::vector<size_t>& order) {
  std::vector<size_t> batch(order.begin(), order.begin() + std::min(order.size(), capacity_));
  std::vector<size_t> missing;
  for (size_t i : batch) {
    if (i >= frames_) throw Error("texture: frame " + std::to_string(i) + " is not among the views");
    if (!resident_.count(i) && std::find(missing.begin(), missing.end(), i) == missing.end()) missing.push_back(i);
  }
  if (missing.empty()) return;
  EvictTo(capacity_ - missing.size(), batch);
  std::vector<cv::Mat> images(missing.size());
  tbb::parallel_for(size_t{0}, missing.size(), [&](size_t k) { images[k] = load_(missing[k]); });
  for (size_t k = 0; k < missing.size(); ++k) Insert(missing[k], std::move(images[k]));
}

void FrameWindow::ForEach(std::vector<size_t> frames, const std::function<void(size_t, const cv::Mat&)>& fn,
                          bool ascending) {
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  last_descending_ = !ascending && !last_descending_;
  if (last_descending_) std::reverse(frames.begin(), frames.end());
  for (size_t b = 0; b < frames.size(); b += capacity_) {
    const std::vector<size_t> batch(frames.begin() + b, frames.begin() + std::min(frames.size(), b + capacity_));
    Prefetch(batch);
    for (size_t i : batch) fn(i, Get(i));
  }
}

}  // namespace fmv3d::surface
