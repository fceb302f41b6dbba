// Descriptor matching: FLANN randomized kd-trees vs brute force (OpenCV SIMD batchDistance), per pair, as a
// function of the number of features per image. Real SIFT from fountain-P11 images 0000/0001 (../shared/data)
// when present, else from two synthetic textured images related by a homography.
// Run: build/bench/match_bench --benchmark_min_time=1  (single-threaded: one pair at a time, as in the stage)
// Measured here (AMD EPYC, AVX2/AVX-512, CPU time per pair incl. building the search structures):
//   features   brute force (ours, AVX2 int16)   FLANN 4 trees / 128 checks   (OpenCV batchDistance BF: 930 ms @8k)
//     1000          2.7 ms                          52 ms
//     2000          9.4 ms                         115 ms
//     4000           34 ms                         295 ms
//     8000          127 ms                         761 ms
// FLANN alone at 8000: build 70 ms per image, 8000 2-NN queries 143 / 278 / 547 ms at 32 / 64 / 128 checks.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <opencv2/flann.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "fmv3d/features/matcher.h"
#include "fmv3d/features/sift.h"

namespace fs = std::filesystem;
using namespace fmv3d::features;

namespace {

// ../shared/data beside the checkout (the bench is built from the source tree; FMV3D_SHARED_DATA overrides).
fs::path SharedData() {
  if (const char* env = std::getenv("FMV3D_SHARED_DATA")) return env;
  return fs::path(__FILE__).parent_path() / "../../shared/data";
}

struct Data {
  FeatureSet a, b;
};

const Data& GetData() {
  static Data d = [] {
    cv::setNumThreads(1);
    SiftOptions so;
    so.max_features = 8000;
    Data out;
    const fs::path dir = SharedData() / "mvs/fountain-P11/images";
    if (fs::exists(dir / "0000.jpg")) {
      out.a = ExtractSift(cv::imread((dir / "0000.jpg").string()), so);
      out.b = ExtractSift(cv::imread((dir / "0001.jpg").string()), so);
    } else {
      cv::Mat img(1536, 2048, CV_8UC3);
      cv::RNG rng(1);
      rng.fill(img, cv::RNG::UNIFORM, 0, 255);
      cv::GaussianBlur(img, img, cv::Size(0, 0), 3);
      cv::Mat warped;
      cv::Mat H = (cv::Mat_<double>(3, 3) << 0.95, 0.05, 20, -0.04, 0.97, 10, 1e-5, 0, 1);
      cv::warpPerspective(img, warped, H, img.size());
      out.a = ExtractSift(img, so);
      out.b = ExtractSift(warped, so);
    }
    return out;
  }();
  return d;
}

Descriptors Head(const Descriptors& d, int n) { return d.topRows(std::min<int>(n, d.rows())); }

void Run(benchmark::State& state, MatcherType type) {
  const auto& d = GetData();
  const int n = static_cast<int>(state.range(0));
  const Descriptors a = Head(d.a.descriptors, n), b = Head(d.b.descriptors, n);
  MatchOptions o;
  o.type = type;
  size_t matches = 0;
  for (auto _ : state) {
    // Fresh descriptors each time: the kd-tree build is part of the cost (once per image in the stage).
    ImageDescriptors ia(a, 1), ib(b, 2);
    matches = MatchDescriptors(ia, ib, o).size();
    benchmark::DoNotOptimize(matches);
  }
  state.counters["features"] = a.rows();
  state.counters["matches"] = static_cast<double>(matches);
}

void BM_Flann(benchmark::State& s) { Run(s, MatcherType::kFlann); }
void BM_BruteForce(benchmark::State& s) { Run(s, MatcherType::kBruteForce); }

}  // namespace

BENCHMARK(BM_Flann)->Arg(500)->Arg(1000)->Arg(2000)->Arg(4000)->Arg(8000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BruteForce)->Arg(500)->Arg(1000)->Arg(2000)->Arg(4000)->Arg(8000)->Unit(benchmark::kMillisecond);

namespace {
// The parts of the FLANN matcher: building one image's kd-forest, and 2-NN queries of all of the other's.
void BM_FlannBuild(benchmark::State& state) {
  const auto& d = GetData();
  const Descriptors a = Head(d.a.descriptors, static_cast<int>(state.range(0)));
  MatchOptions o;
  for (auto _ : state) {
    ImageDescriptors ia(a, 1);
    benchmark::DoNotOptimize(&ia.Index(o));
  }
}
void BM_FlannQuery(benchmark::State& state) {
  const auto& d = GetData();
  const int n = static_cast<int>(state.range(0));
  const Descriptors a = Head(d.a.descriptors, n), b = Head(d.b.descriptors, n);
  MatchOptions o;
  o.flann_checks = static_cast<int>(state.range(1));
  ImageDescriptors ia(a, 1), ib(b, 2);
  ib.Index(o);
  cv::Mat idx, dist;
  for (auto _ : state) ib.Index(o).knnSearch(ia.data(), idx, dist, 2, cv::flann::SearchParams(o.flann_checks));
}
}  // namespace
BENCHMARK(BM_FlannBuild)->Arg(8000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FlannQuery)->Args({8000, 32})->Args({8000, 64})->Args({8000, 128})->Unit(benchmark::kMillisecond);
