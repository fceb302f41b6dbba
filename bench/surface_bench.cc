// Surface + texture stages on a synthetic flight around the `building` scene with about a million oriented
// points (issue 6: Poisson + texturing of 1M oriented points ≤ 60 s on 2 cores), with the accuracy figures
// of the same run: Poisson mesh vs the true scene (RMS, completeness, as % of the building height) and the
// textured model rendered from a held-out true camera vs its frame (PSNR over the covered pixels).
//
//   build/surface_bench [--benchmark_filter=...]     env FMV3D_BENCH_POINTS_SPACING (m, default 0.085),
//                                                    FMV3D_BENCH_FRAMES (default 24), FMV3D_BENCH_SIZE (1280x720),
//                                                    FMV3D_BENCH_DIR (scratch root), FMV3D_BENCH_KEEP (keep files)
#include <benchmark/benchmark.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/surface/mesh_stage.h"
#include "fmv3d/surface/synthetic_cloud.h"
#include "fmv3d/surface/texture_stage.h"
#include "fmv3d/synth/synth.h"

namespace {

namespace fs = std::filesystem;
using namespace fmv3d;

const char* kHeldOut = "flight-000005.png";

// Process CPU seconds (all threads), so the figure means something on a shared, loaded machine too.
double ProcessCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double EnvDouble(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v ? std::atof(v) : fallback;
}

struct Setup {
  fs::path root, synth_dir, ws;
  double length = 0;
  surface::SyntheticCloud cloud;
  double prepare_seconds = 0;
  ~Setup() {
    std::error_code ec;
    if (!std::getenv("FMV3D_BENCH_KEEP")) fs::remove_all(root, ec);
  }
};

Setup& Get() {
  static std::unique_ptr<Setup> s = [] {
    auto s = std::make_unique<Setup>();
    const char* dir = std::getenv("FMV3D_BENCH_DIR");
    s->root = (dir ? fs::path(dir) : fs::temp_directory_path()) / ("fmv3d-surface-bench-" + std::to_string(::getpid()));
    fs::create_directories(s->root);
    synth::SynthOptions o;
    const char* scene = std::getenv("FMV3D_BENCH_SCENE");  // building (default) | town | terrain
    o.scene = scene ? synth::ParseScene(scene) : synth::SceneKind::kBuilding;
    o.flight.frames = static_cast<int>(EnvDouble("FMV3D_BENCH_FRAMES", 24));
    o.width = 1280;
    o.height = 720;
    if (const char* size = std::getenv("FMV3D_BENCH_SIZE")) std::sscanf(size, "%dx%d", &o.width, &o.height);
    o.truth_points = 100;
    o.output = s->synth_dir = s->root / "synth";
    s->length = synth::RunSynth(o).characteristic_length;
    const auto t = std::chrono::steady_clock::now();
    surface::SyntheticCloudOptions c;
    c.spacing = EnvDouble("FMV3D_BENCH_POINTS_SPACING", 0.085);
    c.position_noise = 0.001 * s->length;  // 0.1% of the building height per axis
    c.normal_noise_deg = 5;
    c.outlier_share = 0.01;
    c.outlier_range = 2;
    c.region = Eigen::AlignedBox3d(Eigen::Vector3d(-40, -40, -3), Eigen::Vector3d(40, 40, 35));
    if (o.scene != synth::SceneKind::kBuilding) {  // the modelled area of truth.json (not synth's backdrop ring)
      const auto b = core::ReadJson(s->synth_dir / "truth.json").at("bounds");
      c.region = Eigen::AlignedBox3d(
          Eigen::Vector3d(b.at("min")[0].get<double>(), b.at("min")[1].get<double>(), b.at("min")[2].get<double>()),
          Eigen::Vector3d(b.at("max")[0].get<double>(), b.at("max")[1].get<double>(), b.at("max")[2].get<double>()));
    }
    s->ws = s->root / "ws";
    s->cloud = surface::PrepareSyntheticWorkspace(s->synth_dir, s->ws, c, {kHeldOut});
    s->prepare_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    return s;
  }();
  return *s;
}

void BM_MeshStage(benchmark::State& state) {
  Setup& s = Get();
  nlohmann::json report;
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) report = surface::RunMeshStage(s.ws, surface::MeshStageOptions{});
  state.counters["process_cpu_s"] = ProcessCpuSeconds() - cpu0;
  const surface::ColoredMesh mesh = surface::ReadMeshPly(s.ws / "mesh/poisson.ply");
  const geometry::MeshDistance truth(io::ReadObj(s.synth_dir / "scene.obj", false));
  const auto acc = surface::EvaluateMesh(mesh, truth, s.cloud.seen_surface, 0.1, 0.01 * s.length);
  state.counters["points"] = static_cast<double>(s.cloud.cloud.size());
  state.counters["faces"] = static_cast<double>(mesh.triangles.size());
  state.counters["depth"] = report["poisson"]["depth"].get<int>();
  state.counters["rms_pct"] = 100 * acc.rms / s.length;
  state.counters["median_pct"] = 100 * acc.median / s.length;
  state.counters["complete_pct"] = 100 * acc.completeness;
  state.counters["pieces_found"] = report["poisson"]["components"]["found"].get<double>();
  state.counters["pieces_kept"] = report["poisson"]["components"]["kept"].get<double>();
}
BENCHMARK(BM_MeshStage)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_TextureStage(benchmark::State& state) {
  Setup& s = Get();
  if (!fs::exists(s.ws / "mesh/poisson.ply")) surface::RunMeshStage(s.ws, surface::MeshStageOptions{});
  nlohmann::json report;
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) report = surface::RunTextureStage(s.ws, surface::TextureStageOptions{});
  state.counters["process_cpu_s"] = ProcessCpuSeconds() - cpu0;
  // Held-out view: render the textured model from its true pose and compare with the frame.
  const core::Reconstruction truth = io::ReadColmapText(s.synth_dir / "truth");
  const core::Image* im = truth.FindImageByName(kHeldOut);
  const io::TexturedMesh textured = io::ReadObj(s.ws / "mesh/textured.obj");
  const render::Renderer renderer(textured);
  render::RenderOptions ro;
  ro.shading = false;
  const auto r = renderer.Render(truth.cameras.at(im->camera_id), im->pose, ro);
  const cv::Mat frame = cv::imread((s.synth_dir / "frames" / kHeldOut).string());
  if (std::getenv("FMV3D_BENCH_KEEP")) cv::imwrite((s.ws / "held_out_render.png").string(), r.image);
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x) {
      if (r.face.at<int32_t>(y, x) < 0) continue;
      const cv::Vec3b &a = r.image.at<cv::Vec3b>(y, x), &b = frame.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) se += (a[c] - b[c]) * (a[c] - b[c]);
      n += 3;
    }
  state.counters["faces"] = report["faces"].get<double>();
  state.counters["views"] = report["views"].get<double>();
  state.counters["pages"] = report["atlas"]["pages"].get<double>();
  state.counters["psnr_db"] = 10 * std::log10(255.0 * 255.0 / (se / std::max<size_t>(n, 1)));
  state.counters["covered_pct"] = 100.0 * (static_cast<double>(n) / 3) / (frame.rows * frame.cols);
}
BENCHMARK(BM_TextureStage)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace
