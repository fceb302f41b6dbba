// Registration speed: scaled point-to-plane ICP of a noisy, similarity-moved copy of a sampled building
// (N source points against the same number of target points, start 2° / 2% off), kd-tree build + queries,
// and the CAD comparison's distance pass. Run: build/bench/align_bench --benchmark_min_time=1
#include <benchmark/benchmark.h>

#include <random>

#include "fmv3d/align/icp.h"
#include "fmv3d/align/point_index.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/synth/scene.h"

namespace {

using namespace fmv3d;

io::OrientedPointCloud Building(size_t target_points) {
  const io::TexturedMesh mesh = synth::MakeBuilding(synth::BuildingSpec{}, 0);
  const geometry::MeshDistance md(mesh);
  const double spacing = std::sqrt(mesh.SurfaceArea() / target_points);
  std::vector<int> faces;
  io::OrientedPointCloud c;
  c.positions = md.SampleSurface(spacing, &faces, 1);
  for (int f : faces) c.normals.push_back(md.Normal(f).cast<float>());
  return c;
}

void BM_ScaledIcp(benchmark::State& state) {
  const io::OrientedPointCloud a = Building(state.range(0));
  core::Sim3 truth;
  truth.s = 1.7;
  truth.q = Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, 2, 3).normalized());
  truth.t = Eigen::Vector3d(5, -3, 2);
  std::mt19937_64 rng(1);
  std::normal_distribution<double> g(0, 0.005);
  io::OrientedPointCloud b;
  for (const auto& p : a.positions) b.positions.push_back(truth.Apply(p) + Eigen::Vector3d(g(rng), g(rng), g(rng)));
  core::Sim3 off;
  off.s = 1.02;
  off.q = Eigen::AngleAxisd(2 * M_PI / 180, Eigen::Vector3d::UnitZ());
  const core::Sim3 start = align::ComposeSim3(off, truth.Inverse());
  const align::IcpTarget target(a);
  align::IcpOptions o;
  o.max_source_points = 0;
  int iterations = 0;
  for (auto _ : state) {
    const auto r = align::ScaledIcp(b, target, start, o);
    iterations = r.iterations;
    benchmark::DoNotOptimize(r.transform.s);
  }
  state.counters["points"] = static_cast<double>(a.size());
  state.counters["iterations"] = iterations;
}
BENCHMARK(BM_ScaledIcp)->Arg(20000)->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_PointIndexBuildAndQuery(benchmark::State& state) {
  const io::OrientedPointCloud a = Building(state.range(0));
  for (auto _ : state) {
    const align::PointIndex index(a.positions);
    double sum = 0;
    for (const auto& p : a.positions) {
      double d2 = 0;
      index.Nearest(p + Eigen::Vector3d(0.01, 0.02, 0.03), &d2);
      sum += d2;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.counters["points"] = static_cast<double>(a.size());
}
BENCHMARK(BM_PointIndexBuildAndQuery)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond);

}  // namespace
