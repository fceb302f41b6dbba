// The views fusion works on, held in a bounded window: fusion visits the references in id order, and each
// reference needs only itself and its neighbours at once, so views are loaded on demand and the least recently
// used one is dropped when the window is full (a video's neighbours are near in id: few reloads). Memory is
// then the window's views (~13 bytes per pixel) and not every reference's, whatever the number of frames.
//
// Each view's "used" mask (pixels already emitted as part of a point) must outlive its eviction: an evicted
// mask is kept PNG-compressed (a few KB: the used pixels form a few large regions), so the state that persists
// across the whole fusion is about 1% of a view per view.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/mvs/fusion.h"

namespace fmv3d::mvs {

// Bytes fusion holds per pixel of a view in the window: depth (float), normal (3 × int8), colour (3 × uint8),
// texture precision (float16, when the uncertainty filter is on) and the used mask (uint8).
constexpr double kFusionBytesPerPixel = 13;

// How many views the window holds: as many as fit `budget_mb` at `bytes_per_view` each, at least `min_views`
// (a reference and all its neighbours at once) and at most `views` (all of them: nothing is reloaded).
size_t ChooseFusionWindow(size_t views, size_t min_views, double bytes_per_view, double budget_mb);

class FusionWindow {
 public:
  // A view in the window and its used mask (CV_8U, 1 = emitted). Held by shared_ptr: a slot in use (pinned by
  // its holder) is never evicted, so a mask being written is never compressed meanwhile.
  struct Slot {
    FusionView view;
    cv::Mat used;
  };
  // `load(id)` gives a view with its map, colour and (when wanted) texture, not yet eroded; `ids` ascending.
  FusionWindow(std::vector<uint32_t> ids, std::function<FusionView(uint32_t)> load, size_t capacity,
               const FusionOptions& options);

  // One pass over every view (in id order): drops the pieces its sparse points contradict and erodes its
  // occluding edges (counted in st: sparse_pieces, sparse_pixels, edge_pixels) and,
  // when `texture_samples`, histograms the texture precision at every 4th pixel with a depth (for Quantile).
  void Survey(FusionStats* st, bool texture_samples);
  // The q-quantile of the surveyed texture precision samples (the value std::nth_element would give at
  // index min(n - 1, q·n)); 0 when there were none.
  double TextureQuantile(double q) const;

  std::shared_ptr<Slot> Get(uint32_t id);
  // Drops every view and mask (after the last Get).
  void Release();
  const std::vector<uint32_t>& ids() const { return ids_; }
  bool Contains(uint32_t id) const;

  size_t capacity() const { return capacity_; }
  size_t loads() const { return loads_; }  // views loaded (more than ids().size() when some were evicted)
  size_t peak_resident() const { return peak_resident_; }  // most views held at once
  size_t spilled_mask_bytes() const;                       // compressed masks of the evicted views

 private:
  std::shared_ptr<Slot> Load(uint32_t id, FusionStats* st);  // st: counts of the survey pass (else nullptr)
  void Evict();

  std::vector<uint32_t> ids_;
  std::function<FusionView(uint32_t)> load_;
  size_t capacity_;
  FusionOptions options_;
  std::map<uint32_t, std::pair<uint64_t, std::shared_ptr<Slot>>> resident_;  // id → (last use, slot)
  std::map<uint32_t, std::vector<uchar>> spilled_used_;                      // id → PNG of its used mask
  std::vector<uint64_t> texture_histogram_;  // counts per float16 bit pattern (all samples are positive)
  uint64_t clock_ = 0;
  size_t loads_ = 0, peak_resident_ = 0;
};

}  // namespace fmv3d::mvs
