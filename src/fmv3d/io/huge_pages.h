// Large images on transparent huge pages.
//
// A 12 MP photo's SIFT scale space is about 1.4 GB of float images (its first octave is the image doubled),
// allocated and freed again for every image and every contrast threshold tried. glibc maps each such block afresh,
// so every 4 KiB page of it faults in: on a 2-core VM that was 40% of the features stage's time (75 of 179 s on
// 18 × 12 MP photos) and most of the rest went to TLB misses. Backed by 2 MiB pages (madvise, which Debian's
// default "madvise" THP mode honours), the same stage took 63 s. Outputs are byte-identical: only where the
// memory comes from changes.
#pragma once

#include <cstddef>

namespace fmv3d::io {

// Makes OpenCV allocate every matrix of at least `min_bytes` in its own mapping advised for huge pages (smaller
// ones as before). Process-wide and permanent: the allocator is never destroyed, so matrices allocated by any
// thread stay valid. The first call decides; later calls do nothing. Where the kernel has THP disabled the
// advice is ignored and the mappings behave as glibc's own. Never throws: without it only speed is lost.
void UseHugePagesForLargeMatrices(size_t min_bytes = size_t{8} << 20) noexcept;

// While one of these lives, the large matrices freed keep their mappings for later matrices of the same size
// (rounded up to whole huge pages) instead of returning them to the kernel, which zeroes every page of a fresh
// mapping again: SIFT's scale space, rebuilt for every image and contrast threshold, spent a third of the
// features stage there. A fresh mapping first unmaps kept ones of at least its size, so the memory mapped never
// exceeds the most ever in use. The last scope to end unmaps what is kept. Nothing changes without
// UseHugePagesForLargeMatrices.
class ScopedMatrixReuse {
 public:
  // Bytes of the mappings kept for reuse now (0 outside any scope).
  static size_t KeptBytes() noexcept;

  ScopedMatrixReuse();
  ~ScopedMatrixReuse();
  ScopedMatrixReuse(const ScopedMatrixReuse&) = delete;
  ScopedMatrixReuse& operator=(const ScopedMatrixReuse&) = delete;

 private:
  void* allocator_;
};

}  // namespace fmv3d::io
