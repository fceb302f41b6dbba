#include "fmv3d/mvs/fusion_window.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/error.h"

namespace fmv3d::mvs {

size_t ChooseFusionWindow(size_t views, size_t min_views, double bytes_per_view, double budget_mb) {
  if (!(budget_mb > 0)) throw Error("fusion: the memory budget must be > 0 MB");
  if (!(bytes_per_view > 0)) throw Error("fusion: a view's size must be > 0 bytes");
  const double fit = std::floor(budget_mb * 1048576.0 / bytes_per_view);
  const size_t fitting = fit >= static_cast<double>(views) ? views : static_cast<size_t>(std::max(fit, 0.0));
  return std::min(views, std::max({fitting, min_views, size_t{1}}));
}

FusionWindow::FusionWindow(std::vector<uint32_t> ids, std::function<FusionView(uint32_t)> load, size_t capacity,
                           const FusionOptions& options)
    : ids_(std::move(ids)), load_(std::move(load)), capacity_(std::max<size_t>(capacity, 1)), options_(options) {
  if (!std::is_sorted(ids_.begin(), ids_.end())) throw Error("fusion: view ids must be ascending");
}

bool FusionWindow::Contains(uint32_t id) const { return std::binary_search(ids_.begin(), ids_.end(), id); }

std::shared_ptr<FusionWindow::Slot> FusionWindow::Load(uint32_t id, FusionStats* st) {
  auto slot = std::make_shared<Slot>();
  slot->view = load_(id);
  ++loads_;
  FusionView& v = slot->view;
  // The pieces the view's own sparse points contradict go first: the erosion below would split them.
  if (options_.sparse_tolerance > 0 && !v.sparse.empty()) {
    size_t pieces = 0;
    const cv::Mat mask = SparseContradictionMask(v.depth, SparseDepthsIn(v.geom, v.sparse, options_.sparse_tolerance),
                                                 options_.edge_depth_jump, options_.sparse_min_votes, &pieces);
    if (st) {
      st->sparse_pieces += pieces;
      st->sparse_pixels += static_cast<size_t>(cv::countNonZero(mask));
    }
    v.depth.setTo(0, mask);
  }
  if (options_.edge_erosion_px > 0) {
    const cv::Mat mask =
        OccludingEdgeMask(v.depth, v.normal, v.geom, options_.edge_erosion_px, options_.edge_depth_jump);
    if (st) st->edge_pixels += static_cast<size_t>(cv::countNonZero(mask));
    v.depth.setTo(0, mask);
  }
  if (auto it = spilled_used_.find(id); it != spilled_used_.end()) {
    slot->used = cv::imdecode(it->second, cv::IMREAD_UNCHANGED);
    if (slot->used.size() != v.depth.size() || slot->used.type() != CV_8U)
      throw Error("fusion: view " + std::to_string(id) + " changed size between loads");
    spilled_used_.erase(it);
  } else {
    slot->used = cv::Mat::zeros(v.depth.size(), CV_8U);
  }
  return slot;
}

// Drops least recently used views that nobody holds until the window is within its capacity; a view in use
// stays (the window then briefly exceeds its capacity rather than lose a mask being written).
void FusionWindow::Evict() {
  while (resident_.size() > capacity_) {
    auto victim = resident_.end();
    for (auto it = resident_.begin(); it != resident_.end(); ++it)
      if (it->second.second.use_count() == 1 && (victim == resident_.end() || it->second.first < victim->second.first))
        victim = it;
    if (victim == resident_.end()) return;
    const cv::Mat& used = victim->second.second->used;
    if (cv::countNonZero(used) > 0) {
      std::vector<uchar> png;
      cv::imencode(".png", used, png, {cv::IMWRITE_PNG_COMPRESSION, 1});
      spilled_used_[victim->first] = std::move(png);
    }
    resident_.erase(victim);
  }
}

std::shared_ptr<FusionWindow::Slot> FusionWindow::Get(uint32_t id) {
  auto it = resident_.find(id);
  if (it == resident_.end()) {
    if (!Contains(id)) throw Error("fusion: view " + std::to_string(id) + " is not among the fused views");
    it = resident_.emplace(id, std::make_pair(uint64_t{0}, Load(id, nullptr))).first;
  }
  it->second.first = ++clock_;
  std::shared_ptr<Slot> slot = it->second.second;  // held before eviction: never the victim
  Evict();
  peak_resident_ = std::max(peak_resident_, resident_.size());
  return slot;
}

void FusionWindow::Survey(FusionStats* st, bool texture_samples) {
  texture_histogram_.assign(texture_samples ? 65536 : 0, 0);
  for (uint32_t id : ids_) {
    std::shared_ptr<Slot> slot;
    if (auto it = resident_.find(id); it != resident_.end()) {
      slot = it->second.second;  // a survey runs once, before any view is loaded: kept for safety
    } else {
      slot = Load(id, st);
      resident_.emplace(id, std::make_pair(uint64_t{0}, slot));
    }
    resident_[id].first = ++clock_;
    const FusionView& v = slot->view;
    if (texture_samples && !v.texture.empty())
      for (int y = 0; y < v.depth.rows; y += 4)
        for (int x = 0; x < v.depth.cols; x += 4)
          if (v.depth.at<float>(y, x) > 0) {
            ++texture_histogram_[v.texture.at<cv::float16_t>(y, x).bits()];
          }
    slot.reset();
    Evict();
    peak_resident_ = std::max(peak_resident_, resident_.size());
  }
}

double FusionWindow::TextureQuantile(double q) const {
  uint64_t n = 0;
  for (uint64_t c : texture_histogram_) n += c;
  if (n == 0 || !(q > 0)) return 0;
  // Positive float16 values order as their bit patterns do, so the k-th smallest sample is found by counting.
  const uint64_t k = std::min(n - 1, static_cast<uint64_t>(q * static_cast<double>(n)));
  uint64_t below = 0;
  for (size_t bits = 0; bits < texture_histogram_.size(); ++bits) {
    below += texture_histogram_[bits];
    if (below > k) {
      return static_cast<float>(cv::float16_t::fromBits(static_cast<ushort>(bits)));
    }
  }
  return 0;
}

void FusionWindow::Release() {
  resident_.clear();
  spilled_used_.clear();
}

size_t FusionWindow::spilled_mask_bytes() const {
  size_t n = 0;
  for (const auto& [id, png] : spilled_used_) n += png.size();
  return n;
}

}  // namespace fmv3d::mvs
