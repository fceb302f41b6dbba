// Tiled vs whole-image SIFT (features/sift_memory.h): compares every .feat of two features folders of the same
// frames — $FMV3D_FEAT_REF (e.g. extracted whole, the default budget) and $FMV3D_FEAT_OTHER (e.g. tiled at
// `features --max-memory 256`) — and reports which share of the reference keypoints the other holds identically
// or within 0.01 px (features/feature_compare.h), and the descriptor distance of those. Skips without the folders.
// Run: FMV3D_FEAT_REF=A/features FMV3D_FEAT_OTHER=B/features build/bench/feat_compare_bench
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "fmv3d/features/feature_compare.h"
#include "fmv3d/features/feature_io.h"

namespace {
namespace fs = std::filesystem;

void BM_CompareFeatureFolders(benchmark::State& state) {
  const char* ref = std::getenv("FMV3D_FEAT_REF");
  const char* other = std::getenv("FMV3D_FEAT_OTHER");
  if (!ref || !other || !fs::is_directory(ref) || !fs::is_directory(other)) {
    state.SkipWithError("set FMV3D_FEAT_REF and FMV3D_FEAT_OTHER to two features folders");
    return;
  }
  fmv3d::features::KeypointAgreement total;
  size_t images = 0;
  for (auto _ : state) {
    for (const auto& entry : fs::directory_iterator(ref)) {
      if (entry.path().extension() != ".feat" || !fs::exists(fs::path(other) / entry.path().filename())) continue;
      const auto a = fmv3d::features::ReadFeatures(entry.path());
      const auto b = fmv3d::features::ReadFeatures(fs::path(other) / entry.path().filename());
      const auto one = fmv3d::features::CompareKeypoints(a, b);
      std::cout << entry.path().filename().string() << ": " << one.reference << " / " << one.other
                << " keypoints, identical " << one.identical_share() << ", within 0.01 px " << one.within_share()
                << ", descriptor distance mean " << one.mean_descriptor_distance << " max "
                << one.max_descriptor_distance << "\n";
      total = fmv3d::features::Accumulate(total, one);
      ++images;
    }
  }
  state.counters["images"] = static_cast<double>(images);
  state.counters["reference_keypoints"] = static_cast<double>(total.reference);
  state.counters["other_keypoints"] = static_cast<double>(total.other);
  state.counters["identical_share"] = total.identical_share();
  state.counters["within_share"] = total.within_share();
  state.counters["descriptor_distance_mean"] = total.mean_descriptor_distance;
  state.counters["descriptor_distance_max"] = total.max_descriptor_distance;
}
BENCHMARK(BM_CompareFeatureFolders)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace
