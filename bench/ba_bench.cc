// Bundle adjustment speed on a real model: a COLMAP text model (e.g. a workspace's sparse/) is perturbed (poses
// by ~0.05°/0.1% of the scene, points by ~0.2 px) and adjusted for a fixed number of iterations, so the
// per-iteration cost of the solver choices can be compared. Opt-in:
//   FMV3D_BA_MODEL=WS/sparse build/bench/ba_bench --benchmark_min_time=1
// BM_GlobalBA/<dense_schur_max_images>: 0 forces SPARSE_SCHUR, 100000 DENSE_SCHUR (ITERATIVE_SCHUR with
// SCHUR_JACOBI was tried: 8.3 CPU-s against dense 4.9 for the same 6 iterations).
// BM_LocalBA: the last-registered-like local problem (6 variable images, the rest constant).
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <random>

#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/bundle_adjustment.h"

namespace {

using namespace fmv3d;

const core::Reconstruction* Model() {
  static const core::Reconstruction* rec = [] {
    const char* dir = std::getenv("FMV3D_BA_MODEL");
    return dir ? new core::Reconstruction(io::ReadColmapText(dir)) : nullptr;
  }();
  return rec;
}

core::Reconstruction Perturbed(const core::Reconstruction& in) {
  core::Reconstruction rec = in;
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0, 1);
  Eigen::AlignedBox3d box;
  for (const auto& [id, im] : rec.images) box.extend(im.pose.Centre());
  const double s = box.diagonal().norm();
  for (auto& [id, im] : rec.images) {
    const Eigen::Vector3d w{n(rng), n(rng), n(rng)};
    im.pose.q = (Eigen::Quaterniond(Eigen::AngleAxisd(1e-3 * w.norm(), w.normalized())) * im.pose.q).normalized();
    im.pose.t += 1e-3 * s * Eigen::Vector3d{n(rng), n(rng), n(rng)};
  }
  const double px = 1.0 / rec.cameras.begin()->second.f;
  for (auto& [pid, p] : rec.points) p.xyz += 0.2 * px * p.xyz.norm() * Eigen::Vector3d{n(rng), n(rng), n(rng)};
  return rec;
}

void BM_GlobalBA(benchmark::State& state) {
  if (!Model()) {
    state.SkipWithError("set FMV3D_BA_MODEL to a COLMAP text model folder");
    return;
  }
  const core::Reconstruction start = Perturbed(*Model());
  sfm::BundleAdjustmentOptions o;
  o.dense_schur_max_images = static_cast<int>(state.range(0));
  o.max_iterations = 5;
  o.function_tolerance = 1e-12;
  o.refine_k2 = true;
  for (auto _ : state) {
    state.PauseTiming();
    core::Reconstruction rec = start;
    state.ResumeTiming();
    const auto s = sfm::BundleAdjust(&rec, {}, o);
    state.counters["iterations"] = s.num_iterations;
    state.counters["rms_px"] = s.final_rms_px;
  }
}
BENCHMARK(BM_GlobalBA)->Arg(0)->Arg(100000)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

void BM_LocalBA(benchmark::State& state) {
  if (!Model()) {
    state.SkipWithError("set FMV3D_BA_MODEL to a COLMAP text model folder");
    return;
  }
  const core::Reconstruction start = Perturbed(*Model());
  sfm::BundleAdjustmentConfig cfg;
  auto it = start.images.begin();
  std::advance(it, start.images.size() / 2);
  for (int k = 0; k < 6 && it != start.images.end(); ++k, ++it) cfg.variable_images.insert(it->first);
  for (const auto& [cid, cam] : start.cameras) cfg.constant_cameras.insert(cid);
  sfm::BundleAdjustmentOptions o;
  o.max_iterations = 5;
  o.function_tolerance = 1e-12;
  for (auto _ : state) {
    state.PauseTiming();
    core::Reconstruction rec = start;
    state.ResumeTiming();
    const auto s = sfm::BundleAdjust(&rec, cfg, o);
    state.counters["iterations"] = s.num_iterations;
    state.counters["residuals"] = s.num_residuals;
  }
}
BENCHMARK(BM_LocalBA)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime();

}  // namespace
