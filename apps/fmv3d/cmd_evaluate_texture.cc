// `fmv3d evaluate-texture WS --truth SYNTH_DIR`: the textured model (WS/mesh/textured.obj) rendered from a
// viewpoint of the synthetic flight that no frame has (halfway between its two middle frames) against the true
// frame rendered there, as `fmv3d demo` measures it (pipeline::RenderHeldOut) → PSNR on stdout,
// WS/report/texture_eval.json and truth/model/difference PNGs in WS/report/heldout/. The model is brought
// into the truth frame by the similarity of its cameras to the true ones (sfm::EvaluateSparse).
#include <cstdio>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/pipeline/demo.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/sfm/evaluation.h"

namespace fmv3d::app::cmd_evaluate_texture {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("evaluate-texture",
                                 "PSNR of the textured model from a held-out viewpoint of a synthetic flight");
  struct Args {
    std::string ws, truth;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (with mesh/textured.obj and sparse/)")->required();
  cmd->add_option("--truth", a->truth, "Output folder of `fmv3d synth` (truth/, scene.obj, truth.json)")->required();
  cmd->callback([a] {
    namespace fs = std::filesystem;
    const core::Workspace ws(a->ws);
    ws.Require(ws.sparse_dir() / "images.txt", "sparse");
    ws.Require(ws.mesh_dir() / "textured.obj", "texture");
    const fs::path truth_dir(a->truth);
    for (const char* f : {"truth/images.txt", "scene.obj", "truth.json"})
      if (!fs::exists(truth_dir / f))
        throw Error(a->truth + ": no " + f + " (expected the output folder of `fmv3d synth`)");
    // Light the true frame as synth lit the flight (truth.json "options"; defaults otherwise).
    render::RenderOptions light;
    const auto truth_json = core::ReadJson(truth_dir / "truth.json");
    if (truth_json.contains("options")) {
      const auto& o = truth_json.at("options");
      light.sun_azimuth_deg = o.value("sun_azimuth", light.sun_azimuth_deg);
      light.sun_elevation_deg = o.value("sun_elevation", light.sun_elevation_deg);
      light.ambient = o.value("ambient", light.ambient);
      light.exposure = o.value("exposure", light.exposure);
      light.noise_sigma = o.value("noise", light.noise_sigma);
      light.supersample = o.value("supersample", light.supersample);
    }
    const auto est = io::ReadColmapText(ws.sparse_dir());
    const auto ev = sfm::EvaluateSparse(est, io::ReadColmapText(truth_dir / "truth"));
    const fs::path out = ws.report_dir() / "heldout";
    const pipeline::HeldOutResult r =
        pipeline::RenderHeldOut(truth_dir, ws.mesh_dir() / "textured.obj", ev.alignment, light, out);
    nlohmann::json j = {{"psnr_db", r.psnr_db},
                        {"covered_percent", 100 * r.covered_fraction},
                        {"between_frames", r.between},
                        {"images", out.string()}};
    core::WriteJson(ws.report_dir() / "texture_eval.json", j);
    std::printf("held-out view between %s and %s: PSNR %.2f dB over %.1f%% of the frame (images in %s)\n",
                r.between.at(0).c_str(), r.between.at(1).c_str(), r.psnr_db, 100 * r.covered_fraction,
                out.string().c_str());
  });
}

const RegisterCommand reg(705, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_evaluate_texture
