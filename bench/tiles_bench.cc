// 3D Tiles writing (pipeline/tiles_stage.h): octree build + every .pnts tile written, for 1 M and 10 M points of
// a terrain-like surface (500 x 500 m, colours and normals), 50 000 points per tile. Counters: points, tiles,
// levels, octree seconds, write seconds, peak RSS of the process (MB) and bytes written (MB).
//
//   build/bench/tiles_bench [--benchmark_filter=...]    env FMV3D_BENCH_DIR (scratch root, default /tmp)
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "fmv3d/pipeline/point_octree.h"
#include "fmv3d/pipeline/tiles_stage.h"

namespace {

namespace fs = std::filesystem;
using namespace fmv3d;

std::vector<pipeline::TilePoint> Terrain(size_t n) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 500);
  std::vector<pipeline::TilePoint> pts(n);
  for (auto& p : pts) {
    const float x = u(rng), y = u(rng);
    p.position = {x, y, 20 * std::sin(x / 40) * std::cos(y / 55) + 3 * std::sin(x / 7)};
    p.normal = Eigen::Vector3f(-0.5f * std::cos(x / 40), 0.3f * std::sin(y / 55), 1).normalized();
    p.rgb[0] = static_cast<uint8_t>(x / 2), p.rgb[1] = static_cast<uint8_t>(y / 2), p.rgb[2] = 128;
  }
  return pts;
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void BM_TilesWrite(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  const char* root = std::getenv("FMV3D_BENCH_DIR");
  const fs::path dir = fs::path(root ? root : "/tmp") / ("fmv3d-tiles-bench-" + std::to_string(n));
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(dir);
    std::vector<pipeline::TilePoint> pts = Terrain(n);
    state.ResumeTiming();
    const auto t0 = std::chrono::steady_clock::now();
    pipeline::OctreeOptions o;
    const pipeline::PointOctree tree = pipeline::BuildPointOctree(std::move(pts), o);
    const auto t1 = std::chrono::steady_clock::now();
    pipeline::WritePointTiles(tree, dir);
    const auto t2 = std::chrono::steady_clock::now();
    int levels = 0;
    for (const auto& node : tree.nodes) levels = std::max(levels, node.level + 1);
    size_t bytes = 0;
    for (const auto& e : fs::directory_iterator(dir / "points")) bytes += e.file_size();
    state.counters["points"] = static_cast<double>(tree.points.size());
    state.counters["tiles"] = static_cast<double>(tree.nodes.size());
    state.counters["levels"] = levels;
    state.counters["octree_s"] = std::chrono::duration<double>(t1 - t0).count();
    state.counters["write_s"] = std::chrono::duration<double>(t2 - t1).count();
    state.counters["written_MB"] = bytes / 1e6;
    state.counters["peak_rss_MB"] = PeakRssMb();
  }
  fs::remove_all(dir);
}
BENCHMARK(BM_TilesWrite)->Arg(1000000)->Arg(10000000)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace
