#include "fmv3d/features/sift_memory.h"

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/features/sift.h"

namespace fmv3d::features {
namespace {

// n + 1 edges splitting [0, length) into n parts of near-equal size, inner edges on multiples of `align`.
std::vector<int> SplitEdges(int length, int n, int align) {
  std::vector<int> edges = {0};
  for (int i = 1; i < n; ++i) {
    const double at = static_cast<double>(length) * i / n;
    edges.push_back(static_cast<int>(std::lround(at / align)) * align);
  }
  edges.push_back(length);
  return edges;
}

bool PartsAtLeast(const std::vector<int>& edges, int min_part) {
  for (size_t i = 0; i + 1 < edges.size(); ++i)
    if (edges[i + 1] - edges[i] < min_part) return false;
  return true;
}

// Windows are cores grown by `margin` on each side, clipped to [0, length).
int LargestWindow(const std::vector<int>& edges, int margin, int length) {
  int largest = 0;
  for (size_t i = 0; i + 1 < edges.size(); ++i)
    largest = std::max(largest, std::min(length, edges[i + 1] + margin) - std::max(0, edges[i] - margin));
  return largest;
}

std::vector<SiftTile> MakeTiles(const std::vector<int>& xs, const std::vector<int>& ys, int margin, int width,
                                int height) {
  std::vector<SiftTile> tiles;
  for (size_t j = 0; j + 1 < ys.size(); ++j)
    for (size_t i = 0; i + 1 < xs.size(); ++i) {
      SiftTile t;
      t.core = {xs[i], ys[j], xs[i + 1] - xs[i], ys[j + 1] - ys[j]};
      const int x0 = std::max(0, xs[i] - margin), y0 = std::max(0, ys[j] - margin);
      const int x1 = std::min(width, xs[i + 1] + margin), y1 = std::min(height, ys[j + 1] + margin);
      t.window = {x0, y0, x1 - x0, y1 - y0};
      tiles.push_back(t);
    }
  return tiles;
}

}  // namespace

void ExtractionSize(int width, int height, int max_image_size, int* out_width, int* out_height) {
  const int max_dim = std::max(width, height);
  if (max_dim <= max_image_size) {
    *out_width = width;
    *out_height = height;
    return;
  }
  // As cv::resize computes the size from a scale factor (cvRound: to nearest, ties to even).
  const double scale = static_cast<double>(max_image_size) / max_dim;
  *out_width = static_cast<int>(std::lrint(width * scale));
  *out_height = static_cast<int>(std::lrint(height * scale));
}

double SiftWindowBytes(long long pixels) { return kSiftBytesPerPixel * static_cast<double>(pixels); }

std::vector<SiftTile> PlanSiftTiles(int width, int height, double budget_bytes, double other_bytes,
                                    const TilingLimits& limits, bool* fits) {
  if (width <= 0 || height <= 0) throw Error("features: tiling an empty image");
  if (limits.align <= 0 || limits.margin < 0 || limits.margin % limits.align != 0 || limits.min_core < limits.align)
    throw Error("features: tile margin must be a multiple of the alignment, cores at least one alignment step");
  const int max_nx = std::max(1, width / limits.min_core), max_ny = std::max(1, height / limits.min_core);
  int best_nx = 0, best_ny = 0;
  long long best_count = 0, best_area = 0;
  for (int nx = 1; nx <= max_nx; ++nx) {
    const auto xs = SplitEdges(width, nx, limits.align);
    if (nx > 1 && !PartsAtLeast(xs, limits.min_core)) continue;
    for (int ny = 1; ny <= max_ny; ++ny) {
      const auto ys = SplitEdges(height, ny, limits.align);
      if (ny > 1 && !PartsAtLeast(ys, limits.min_core)) continue;
      const long long area =
          static_cast<long long>(LargestWindow(xs, limits.margin, width)) * LargestWindow(ys, limits.margin, height);
      if (SiftWindowBytes(area) + other_bytes > budget_bytes) continue;
      const long long count = static_cast<long long>(nx) * ny;
      if (best_count == 0 || count < best_count || (count == best_count && area < best_area)) {
        best_nx = nx, best_ny = ny, best_count = count, best_area = area;
      }
    }
  }
  if (fits) *fits = best_count > 0;
  if (best_count == 0) {  // nothing fits: the finest tiling allowed
    best_nx = max_nx, best_ny = max_ny;
    while (best_nx > 1 && !PartsAtLeast(SplitEdges(width, best_nx, limits.align), limits.min_core)) --best_nx;
    while (best_ny > 1 && !PartsAtLeast(SplitEdges(height, best_ny, limits.align), limits.min_core)) --best_ny;
  }
  const auto xs = SplitEdges(width, best_nx, limits.align), ys = SplitEdges(height, best_ny, limits.align);
  // One tile is the whole image (no margin to add).
  if (best_nx == 1 && best_ny == 1) return {SiftTile{{0, 0, width, height}, {0, 0, width, height}}};
  return MakeTiles(xs, ys, limits.margin, width, height);
}

SiftMemoryPlan PlanSiftMemory(int width, int height, const SiftOptions& options, double budget_bytes,
                              const TilingLimits& limits) {
  SiftMemoryPlan plan;
  ExtractionSize(width, height, options.max_image_size, &plan.extraction_width, &plan.extraction_height);
  const double frame = kFrameBytesPerPixel * width * height +
                       static_cast<double>(plan.extraction_width) * plan.extraction_height + kSiftFixedBytes;
  plan.tiles = PlanSiftTiles(plan.extraction_width, plan.extraction_height, budget_bytes, frame, limits, &plan.fits);
  long long largest = 0;
  for (const auto& t : plan.tiles) largest = std::max(largest, t.window.area());
  plan.estimated_bytes = frame + SiftWindowBytes(largest);
  return plan;
}

bool Admits(double in_flight, size_t holders, double request, double budget) {
  return holders == 0 || in_flight + request <= budget;
}

void MemoryGate::Acquire(double bytes) {
  std::unique_lock<std::mutex> lock(mutex_);
  released_.wait(lock, [&] { return Admits(in_flight_, holders_, bytes, budget_); });
  in_flight_ += bytes;
  ++holders_;
  peak_bytes_ = std::max(peak_bytes_, in_flight_);
  peak_holders_ = std::max(peak_holders_, holders_);
}

void MemoryGate::Release(double bytes) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    in_flight_ -= bytes;
    --holders_;
    if (holders_ == 0) in_flight_ = 0;  // no rounding residue
  }
  released_.notify_all();
}

}  // namespace fmv3d::features
