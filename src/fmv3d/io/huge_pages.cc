#include "fmv3d/io/huge_pages.h"

#include <sys/mman.h>

#include <atomic>
#include <opencv2/core.hpp>

namespace fmv3d::io {
namespace {

class HugePageAllocator final : public cv::MatAllocator {
 public:
  HugePageAllocator(const cv::MatAllocator* fallback, size_t min_bytes) : fallback_(fallback), min_bytes_(min_bytes) {}

  cv::UMatData* allocate(int dims, const int* sizes, int type, void* data0, size_t* step, cv::AccessFlag flags,
                         cv::UMatUsageFlags usage) const override {
    if (data0) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    size_t total = CV_ELEM_SIZE(type);
    for (int i = dims - 1; i >= 0; --i) total *= static_cast<size_t>(sizes[i]);
    if (total < min_bytes_) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    void* p = mmap(nullptr, total, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    madvise(p, total, MADV_HUGEPAGE);  // advice only: a kernel without THP keeps 4 KiB pages
    if (step) {                        // dense rows, as the standard allocator lays them out
      size_t s = CV_ELEM_SIZE(type);
      for (int i = dims - 1; i >= 0; --i) {
        step[i] = s;
        s *= static_cast<size_t>(sizes[i]);
      }
    }
    auto* u = new cv::UMatData(this);
    u->data = u->origdata = static_cast<uchar*>(p);
    u->size = total;
    return u;
  }

  bool allocate(cv::UMatData* u, cv::AccessFlag /*flags*/, cv::UMatUsageFlags /*usage*/) const override {
    return u != nullptr;
  }

  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    CV_Assert(u->urefcount == 0 && u->refcount == 0);
    if (!(u->flags & cv::UMatData::USER_ALLOCATED)) munmap(u->origdata, u->size);
    delete u;
  }

 private:
  const cv::MatAllocator* fallback_;
  size_t min_bytes_;
};

}  // namespace

void UseHugePagesForLargeMatrices(size_t min_bytes) noexcept {
  static std::atomic<bool> installed{false};
  if (installed.exchange(true)) return;
  try {
    // Never destroyed: matrices it allocated may outlive any scope.
    static auto* allocator = new HugePageAllocator(cv::Mat::getStdAllocator(), min_bytes);
    cv::Mat::setDefaultAllocator(allocator);
  } catch (...) {  // out of memory at start-up: OpenCV's own allocator stays
  }
}

}  // namespace fmv3d::io
