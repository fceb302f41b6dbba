#include "fmv3d/io/huge_pages.h"

#include <sys/mman.h>

#include <atomic>
#include <map>
#include <mutex>
#include <opencv2/core.hpp>

namespace fmv3d::io {
namespace {

constexpr size_t kHugePage = size_t{2} << 20;

// Mappings are whole huge pages, so that a freed one serves any later matrix of the same rounded size.
size_t MappedBytes(size_t bytes) { return (bytes + kHugePage - 1) / kHugePage * kHugePage; }

class HugePageAllocator final : public cv::MatAllocator {
 public:
  HugePageAllocator(const cv::MatAllocator* fallback, size_t min_bytes) : fallback_(fallback), min_bytes_(min_bytes) {}

  cv::UMatData* allocate(int dims, const int* sizes, int type, void* data0, size_t* step, cv::AccessFlag flags,
                         cv::UMatUsageFlags usage) const override {
    if (data0) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    size_t total = CV_ELEM_SIZE(type);
    for (int i = dims - 1; i >= 0; --i) total *= static_cast<size_t>(sizes[i]);
    if (total < min_bytes_) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    void* p = Map(MappedBytes(total));
    if (!p) return fallback_->allocate(dims, sizes, type, data0, step, flags, usage);
    if (step) {  // dense rows, as the standard allocator lays them out
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
    if (!(u->flags & cv::UMatData::USER_ALLOCATED)) Unmap(u->origdata, MappedBytes(u->size));
    delete u;
  }

  size_t KeptBytes() const {
    const std::lock_guard<std::mutex> lock(mutex_);
    size_t total = 0;
    for (const auto& [bytes, p] : free_) total += bytes;
    return total;
  }

  void BeginReuse() {
    const std::lock_guard<std::mutex> lock(mutex_);
    ++reuse_scopes_;
  }

  void EndReuse() {
    std::multimap<size_t, void*> released;
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (--reuse_scopes_ > 0) return;
      released.swap(free_);
    }
    for (const auto& [bytes, p] : released) munmap(p, bytes);
  }

 private:
  // A kept mapping of exactly this size when there is one; else a fresh one, after unmapping kept ones of at
  // least as many bytes, so that mapped memory (in use + kept) never exceeds the most ever in use.
  void* Map(size_t bytes) const {
    std::multimap<size_t, void*> evicted;
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (const auto it = free_.find(bytes); it != free_.end()) {
        void* p = it->second;
        free_.erase(it);
        return p;
      }
      for (size_t freed = 0; freed < bytes && !free_.empty();) {
        const auto largest = std::prev(free_.end());
        freed += largest->first;
        evicted.insert(*largest);
        free_.erase(largest);
      }
    }
    for (const auto& [b, q] : evicted) munmap(q, b);
    void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return nullptr;
    madvise(p, bytes, MADV_HUGEPAGE);  // advice only: a kernel without THP keeps 4 KiB pages
    return p;
  }

  void Unmap(void* p, size_t bytes) const {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (reuse_scopes_ > 0) {
        free_.emplace(bytes, p);
        return;
      }
    }
    munmap(p, bytes);
  }

  const cv::MatAllocator* fallback_;
  size_t min_bytes_;
  mutable std::mutex mutex_;
  int reuse_scopes_ = 0;                       // guarded by mutex_
  mutable std::multimap<size_t, void*> free_;  // kept mappings by size, guarded by mutex_
};

HugePageAllocator* installed_allocator = nullptr;  // set once, before any scope

}  // namespace

void UseHugePagesForLargeMatrices(size_t min_bytes) noexcept {
  static std::atomic<bool> installed{false};
  if (installed.exchange(true)) return;
  try {
    // Never destroyed: matrices it allocated may outlive any scope.
    static auto* allocator = new HugePageAllocator(cv::Mat::getStdAllocator(), min_bytes);
    cv::Mat::setDefaultAllocator(allocator);
    installed_allocator = allocator;
  } catch (...) {  // out of memory at start-up: OpenCV's own allocator stays
  }
}

size_t ScopedMatrixReuse::KeptBytes() noexcept { return installed_allocator ? installed_allocator->KeptBytes() : 0; }

ScopedMatrixReuse::ScopedMatrixReuse() : allocator_(installed_allocator) {
  if (allocator_) static_cast<HugePageAllocator*>(allocator_)->BeginReuse();
}

ScopedMatrixReuse::~ScopedMatrixReuse() {
  if (allocator_) static_cast<HugePageAllocator*>(allocator_)->EndReuse();
}

}  // namespace fmv3d::io
