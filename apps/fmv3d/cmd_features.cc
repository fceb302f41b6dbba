// `fmv3d features WS`: SIFT keypoints + descriptors for every frame in WS/frames → WS/features/<stem>.feat.
#include <spdlog/spdlog.h>

#include "command.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/sift.h"

namespace fmv3d::app::cmd_features {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("features", "Extract SIFT features for every frame (WS/features/*.feat)");
  struct Args {
    std::string ws;
    features::SiftOptions opt;
    bool no_root_sift = false, force = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (with frames/frames.json)")->required();
  cmd->add_option("--max-features", a->opt.max_features, "Keypoints kept per image (strongest; 0 = all)")
      ->capture_default_str();
  cmd->add_option("--max-image-size", a->opt.max_image_size,
                  "Extract on a downscaled copy when the larger side exceeds this (coordinates rescaled)")
      ->capture_default_str();
  cmd->add_option("--contrast-threshold", a->opt.contrast_threshold,
                  "SIFT contrast threshold (OpenCV scale; OpenCV's default 0.04 keeps far fewer)")
      ->capture_default_str();
  cmd->add_option("--edge-threshold", a->opt.edge_threshold, "SIFT edge threshold")->capture_default_str();
  cmd->add_option("--max-memory", a->opt.max_memory_mb,
                  "Memory budget, MB: images run in parallel while their SIFT working sets fit; a larger image is "
                  "extracted in tiles")
      ->capture_default_str();
  cmd->add_flag("--no-root-sift", a->no_root_sift, "Plain L2-normalised SIFT instead of RootSIFT");
  cmd->add_flag("--upright", a->opt.upright, "One orientation per keypoint (no in-plane rotation expected)");
  cmd->add_flag("--force", a->force, "Re-extract even when a .feat file is newer than its image");
  cmd->callback([a] {
    const core::Workspace ws(a->ws);
    ws.Require(ws.frames_json(), "frames");
    a->opt.root_sift = !a->no_root_sift;
    features::RunFeaturesStage(ws.root(), a->opt, a->force);
  });
}

const RegisterCommand reg(200, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_features
