// `fmv3d evaluate-sparse WS --truth DIR`: accuracy of WS/sparse against ground-truth cameras (a COLMAP text model
// or a Strecha folder of .camera files) → stdout and WS/report/sparse_eval.json.
#include <cstdio>

#include "command.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/sfm/evaluation.h"

namespace fmv3d::app::cmd_evaluate {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate-sparse", "Compare WS/sparse with ground-truth cameras (similarity-aligned)");
  struct Args {
    std::string ws, truth, model;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder")->required();
  cmd->add_option("--truth", a->truth, "Ground truth: COLMAP text model folder, or folder of Strecha .camera files")
      ->required();
  cmd->add_option("--model", a->model, "Model folder to evaluate (default WS/sparse)");
  cmd->callback([a] {
    const core::Workspace ws(a->ws);
    const std::filesystem::path model = a->model.empty() ? ws.sparse_dir() : std::filesystem::path(a->model);
    ws.Require(model / "images.txt", "sparse");
    const auto est = io::ReadColmapText(model);
    const auto truth = sfm::LoadTruth(a->truth);
    const auto ev = sfm::EvaluateSparse(est, truth);
    auto j = ev.ToJson();
    j["registered_images"] = est.images.size();
    j["points"] = est.points.size();
    j["mean_reprojection_error_px"] = est.MeanReprojectionError();
    core::EnsureDirectory(ws.report_dir());
    core::WriteJson(ws.report_dir() / "sparse_eval.json", j);
    std::printf("registered %zu / %d truth images (%d matched by name)\n", est.images.size(), ev.num_truth_images,
                ev.num_matched);
    std::printf("camera centre RMSE %.6g (%.4f%% of extent %.6g; max %.4f%%)\n", ev.centre_rmse,
                100 * ev.centre_rmse_fraction, ev.extent, 100 * ev.max_centre_error_fraction);
    std::printf("median relative rotation error %.4f deg\n", ev.median_rotation_error_deg);
    std::printf("focal relative error %.4f%%\n", 100 * ev.focal_relative_error);
    std::printf("principal point error %.2f px, lens residual at the corners %.3f px\n", ev.principal_point_error_px,
                ev.lens_residual_corner_px);
    std::printf("systematic rotation error (camera x/y/z) %.4f %.4f %.4f deg\n", ev.systematic_rotation_deg.x(),
                ev.systematic_rotation_deg.y(), ev.systematic_rotation_deg.z());
    std::printf("mean reprojection error %.3f px, %zu points\n", est.MeanReprojectionError(), est.points.size());
  });
}

const RegisterCommand reg(410, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_evaluate
