// `fmv3d texture WS`: per-face view selection and a texture atlas for WS/mesh/poisson.ply →
// WS/mesh/textured.obj (+ .mtl, atlas PNGs), model.glb, textured.ply, report/texture.json.
#include "command.h"
#include "fmv3d/surface/texture_stage.h"

namespace fmv3d::app::cmd_texture {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "texture", "Texture the Poisson mesh from the registered frames (WS/mesh/textured.obj, model.glb)");
  struct Args {
    std::string ws;
    surface::TextureStageOptions opt;
  };
  auto a = std::make_shared<Args>();
  auto& s = a->opt.selection;
  auto& t = a->opt.atlas;
  cmd->add_option("WS", a->ws, "Workspace folder (with mesh/poisson.ply, sparse/, frames/)")->required();
  cmd->add_option("--max-angle", s.max_angle_deg, "Views more oblique than this to a face are not used, degrees")
      ->capture_default_str();
  cmd->add_option("--consistency", s.consistency_threshold,
                  "Colour distance (0-255) from the other views' consensus beyond which a view is rejected")
      ->capture_default_str();
  cmd->add_option("--smoothness", s.smoothness, "Weight of neighbouring faces sharing a view (fewer seams)")
      ->capture_default_str();
  cmd->add_option("--visibility-scale", s.visibility_scale,
                  "Render visibility maps at this fraction of the image size (faster, less exact)")
      ->capture_default_str();
  cmd->add_option("--view-coverage", a->opt.view_coverage,
                  "Colour from the fewest views that see every sparse point this many times (0: every view)")
      ->capture_default_str();
  cmd->add_option("--max-memory", a->opt.max_memory_mb,
                  "MB of decoded frames held at once (frames that do not fit are decoded again; same output)")
      ->capture_default_str();
  cmd->add_option("--page-size", t.max_page_size, "Largest atlas page side, texels (power of two)")
      ->capture_default_str();
  cmd->add_option("--texel-scale", t.texel_scale, "Atlas texels per source pixel")->capture_default_str();
  cmd->add_flag("!--no-color-adjustment", t.adjust_colors, "Do not equalise the views' colours across seams");
  cmd->callback([a] { surface::RunTextureStage(a->ws, a->opt); });
}

const RegisterCommand reg(700, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_texture
