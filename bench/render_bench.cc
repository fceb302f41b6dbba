// Rasteriser speed: one 1280x720 frame of the town scene from the default orbit (target: <= 50 ms on 2
// cores), plus scene generation. Run: build/bench/render_bench --benchmark_min_time=2
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include "fmv3d/render/renderer.h"
#include "fmv3d/synth/flight.h"
#include "fmv3d/synth/scene.h"
#include "fmv3d/synth/synth.h"

namespace {

using namespace fmv3d;

// Process CPU time (all threads), seconds: the machine is shared, so wall time alone is misleading.
double ProcessCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

const synth::Scene& Town() {
  static const synth::Scene scene = synth::MakeScene(synth::SceneKind::kTown);
  return scene;
}

void BM_RenderTown720p(benchmark::State& state) {
  const auto& scene = Town();
  synth::SynthOptions o;
  o.width = 1280;
  o.height = 720;
  o.flight.frames = 16;
  o.render.supersample = static_cast<int>(state.range(0));
  const core::Camera cam = synth::SynthCamera(o);
  const auto poses = synth::MakeFlight(scene, cam, o.flight);
  const render::Renderer renderer(scene.mesh);
  size_t k = 0;
  renderer.Render(cam, poses[0], o.render);  // warm-up (buffers)
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) {
    auto r = renderer.Render(cam, poses[k++ % poses.size()], o.render);
    benchmark::DoNotOptimize(r.image.data);
  }
  state.counters["cpu_ms_per_frame"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations();
  state.SetLabel("supersample " + std::to_string(state.range(0)));
}
BENCHMARK(BM_RenderTown720p)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RenderTown720pDistorted(benchmark::State& state) {
  const auto& scene = Town();
  synth::SynthOptions o;
  o.distortion = {-0.12, 0.03, 0.001, -0.0005};
  const core::Camera cam = synth::SynthCamera(o);
  const auto poses = synth::MakeFlight(scene, cam, o.flight);
  const render::Renderer renderer(scene.mesh);
  size_t k = 0;
  renderer.Render(cam, poses[0], o.render);  // warm-up (ray table)
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) {
    auto r = renderer.Render(cam, poses[k++ % poses.size()], o.render);
    benchmark::DoNotOptimize(r.image.data);
  }
  state.counters["cpu_ms_per_frame"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations();
}
BENCHMARK(BM_RenderTown720pDistorted)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_MakeTownScene(benchmark::State& state) {
  for (auto _ : state) {
    auto s = synth::MakeScene(synth::SceneKind::kTown);
    benchmark::DoNotOptimize(s.mesh.faces.data());
  }
}
BENCHMARK(BM_MakeTownScene)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

}  // namespace
