// `fmv3d evaluate-dense WS --truth SYNTH_DIR`: accuracy and completeness of WS/dense/fused.ply against the
// synthetic scene of `fmv3d synth` (truth/, scene.obj, truth.json) → stdout table + WS/report/dense_eval.json.
#include <cstdio>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/mvs/evaluation.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/surface/colored_mesh.h"

namespace fmv3d::app::cmd_evaluate_dense {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate-dense", "Compare WS/dense/fused.ply with a synthetic scene's true mesh");
  struct Args {
    std::string ws, truth, cloud, mesh, missed;
    bool everywhere = false;
    mvs::DenseEvaluationOptions opt;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder")->required();
  cmd->add_option("--truth", a->truth, "Output folder of `fmv3d synth` (truth/, scene.obj, truth.json)")->required();
  cmd->add_option("--cloud", a->cloud, "Point cloud to evaluate (default WS/dense/fused.ply)");
  cmd->add_option("--mesh", a->mesh,
                  "Evaluate a mesh instead (e.g. WS/mesh/poisson.ply): its surface sampled every 0.1% of the length")
      ->excludes("--cloud");
  cmd->add_option("--completeness", a->opt.completeness_fraction,
                  "Completeness distance, fraction of the characteristic length")
      ->capture_default_str();
  cmd->add_option("--missed", a->missed,
                  "Write the seen surface samples with no point near (truth frame, PLY) to see where completeness "
                  "is lost");
  cmd->add_flag("--everywhere", a->everywhere,
                "Completeness over all seen surface, including synth's backdrop beyond truth.json bounds");
  cmd->callback([a] {
    namespace fs = std::filesystem;
    const core::Workspace ws(a->ws);
    const fs::path cloud_path = !a->mesh.empty()   ? fs::path(a->mesh)
                                : a->cloud.empty() ? ws.dense_dir() / "fused.ply"
                                                   : fs::path(a->cloud);
    ws.Require(ws.sparse_dir() / "images.txt", "sparse");
    if (!fs::exists(cloud_path))
      throw Error(cloud_path.string() + ": not found — run `fmv3d " + (a->mesh.empty() ? "dense" : "mesh") + "` first");
    const fs::path truth_dir(a->truth);
    for (const char* f : {"truth/images.txt", "scene.obj", "truth.json"})
      if (!fs::exists(truth_dir / f))
        throw Error(a->truth + ": no " + f + " (expected the output folder of `fmv3d synth`)");
    const auto truth_json = core::ReadJson(truth_dir / "truth.json");
    if (!truth_json.contains("characteristic_length"))
      throw Error((truth_dir / "truth.json").string() + ": no characteristic_length");
    const double length = truth_json.at("characteristic_length").get<double>();
    if (truth_json.contains("bounds") && !a->everywhere) {
      const auto& b = truth_json.at("bounds");
      a->opt.region = Eigen::AlignedBox3d(
          Eigen::Vector3d(b.at("min")[0].get<double>(), b.at("min")[1].get<double>(), b.at("min")[2].get<double>()),
          Eigen::Vector3d(b.at("max")[0].get<double>(), b.at("max")[1].get<double>(), b.at("max")[2].get<double>()));
    }
    const auto est = io::ReadColmapText(ws.sparse_dir());
    const auto truth = io::ReadColmapText(truth_dir / "truth");
    const auto scene = io::ReadObj(truth_dir / "scene.obj", false);
    io::OrientedPointCloud cloud;
    if (a->mesh.empty()) {
      cloud = io::ReadPointCloudPly(cloud_path);
    } else {
      // The mesh's surface as evenly spread points, in the estimate's frame (the similarity's scale from the
      // cameras brings the spacing to about 0.1% of the length in the truth frame).
      const auto mesh = surface::ReadMeshPly(cloud_path);
      const double s = sfm::EvaluateSparse(est, truth).alignment.s;
      const geometry::MeshDistance md(mesh.vertices, mesh.triangles);
      cloud.positions = md.SampleSurface(0.001 * length / s, nullptr, 3);
    }
    a->opt.keep_missed = !a->missed.empty();
    const auto ev = mvs::EvaluateDense(cloud, est, truth, scene, length, a->opt);
    if (!a->missed.empty()) {
      io::OrientedPointCloud missed;
      missed.positions = ev.missed_samples;
      io::WritePointCloudPly(missed, a->missed);
    }
    core::EnsureDirectory(ws.report_dir());
    core::WriteJson(ws.report_dir() / (a->mesh.empty() ? "dense_eval.json" : "mesh_eval.json"), ev.ToJson());
    std::printf("%-34s %14s\n", a->mesh.empty() ? "dense cloud vs true mesh" : "mesh surface vs true mesh", "");
    std::printf("%-34s %14zu\n", "points", ev.points);
    std::printf("%-34s %14.4f\n", "characteristic length", length);
    std::printf("%-34s %14.5f  (%.3f%%)\n", "accuracy median", ev.median_error, 100 * ev.median_fraction());
    std::printf("%-34s %14.5f  (%.3f%%)\n", "accuracy p90", ev.p90_error, 100 * ev.p90_fraction());
    std::printf("%-34s %14.5f\n", "accuracy mean", ev.mean_error);
    std::printf("%-34s %14.5f  (%.3f%%)\n", "accuracy RMS", ev.rms_error, 100 * ev.rms_error / length);
    if (!a->opt.region.isEmpty())
      std::printf("%-34s %14s  median %.3f%%, p90 %.3f%%, RMS %.3f%% (%zu points)\n", "accuracy in the region", "",
                  100 * ev.region_median_error / length, 100 * ev.region_p90_error / length,
                  100 * ev.region_rms_error / length, ev.region_points);
    std::printf("%-34s %13.2f%%\n", "points within 1% of length", 100 * ev.within_1_percent);
    std::printf("%-34s %13.2f%%  (%zu of %zu samples seen by >=%d cameras)\n", "completeness (1% of length)",
                100 * ev.completeness, ev.complete_samples, ev.seen_samples, a->opt.min_cameras);
    if (!a->opt.region.isEmpty())
      std::printf("%-34s %13.2f%%  (of %zu samples seen, backdrop included)\n", "completeness, all seen surface",
                  100 * ev.completeness_everywhere, ev.seen_samples_everywhere);
    if (ev.sigma_exceeded >= 0) {
      std::printf("%-34s %13.2f%%  (median sigma %.3f%% of length)\n", "true error > stated sigma",
                  100 * ev.sigma_exceeded, 100 * ev.median_sigma / length);
      if (ev.sigma_exceeded_outside >= 0)
        std::printf("%-34s %13.2f%%\n", "  outside the region (far field)", 100 * ev.sigma_exceeded_outside);
    }
    std::printf("\n%-42s %10s %8s %8s %16s\n", "breakdown", "points", "p50 %", "p90 %", "completeness");
    for (const auto& b : ev.breakdown) {
      if (b.points > 0)
        std::printf("%-42s %10zu %8.3f %8.3f\n", b.name.c_str(), b.points, 100 * b.median_error / length,
                    100 * b.p90_error / length);
      else if (b.seen_samples > 0)
        std::printf("%-42s %10s %8s %8s %7.2f%% of %zu\n", b.name.c_str(), "", "", "",
                    100.0 * static_cast<double>(b.complete_samples) / static_cast<double>(b.seen_samples),
                    b.seen_samples);
    }
  });
}

const RegisterCommand reg(510, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_evaluate_dense
