#include "fmv3d/core/threading.h"

#include <tbb/global_control.h>
#include <tbb/info.h>

#include <memory>

namespace fmv3d::core {
namespace {
std::unique_ptr<tbb::global_control> g_control;
int g_threads = 0;
}  // namespace

void SetNumThreads(int n) {
  g_threads = n > 0 ? n : tbb::info::default_concurrency();
  g_control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, g_threads);
}

int NumThreads() { return g_threads > 0 ? g_threads : tbb::info::default_concurrency(); }

}  // namespace fmv3d::core
