// Thread count for all parallel loops (TBB). Set once from the CLI's --threads; 0 means all cores.
#pragma once

namespace fmv3d::core {

void SetNumThreads(int n);
int NumThreads();

}  // namespace fmv3d::core
