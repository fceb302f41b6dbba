// `fmv3d align WS_A WS_B ... -o WS_MERGED`: bring independent reconstructions of one target into one frame
// (no GPS needed) and merge them (align/tracks.h, align/merge.h).
#include <fmt/format.h>

#include <iostream>

#include "command.h"
#include "fmv3d/align/merge.h"

namespace fmv3d::app::cmd_align {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("align", "Align and merge reconstructions of one target from several flights");
  cmd->footer(
      "Each WS needs sparse/ (fmv3d sparse), features/ and frames/; dense/fused.ply is used for the fine ICP\n"
      "when every track has one. The largest track is the reference frame. Output: WS_MERGED/sparse (COLMAP\n"
      "model of all tracks), frames/, dense/fused.ply (when dense clouds exist), report/align.json.\n"
      "Then one bundle adjustment of all tracks over the fused cross-track points (--no-joint-ba to skip);\n"
      "`fmv3d mesh` / `texture` run on WS_MERGED.\n"
      "Tracks that share nothing: \"no overlap found between A and B\", exit 1, nothing written.");
  struct Args {
    std::vector<std::string> ws;
    std::string out;
    align::TrackAlignOptions opt;
    bool no_icp = false;
    align::MergeOptions merge;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspaces to align (two or more)")
      ->required()
      ->expected(2, -1)
      ->check(CLI::ExistingDirectory);
  cmd->add_option("-o,--output", a->out, "Merged workspace")->required();
  cmd->add_option("--candidates", a->opt.candidates_per_image,
                  "Cross-track image pairs per image by global descriptor (large tracks)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--exhaustive-pairs", a->opt.exhaustive_max_pairs,
                  "Match every cross-track image pair when there are at most this many")
      ->capture_default_str();
  cmd->add_option("--min-inliers", a->opt.min_inliers, "Consistent 3D correspondences needed for overlap")
      ->check(CLI::Range(3, 1000000))
      ->capture_default_str();
  cmd->add_option("--ransac-error", a->opt.ransac_max_error,
                  "3D RANSAC inlier distance, fraction of the reference scene's radius")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--no-icp", a->no_icp, "Skip the fine ICP on dense clouds");
  cmd->add_flag("!--no-joint-ba", a->merge.joint_bundle_adjustment,
                "Skip the joint bundle adjustment of all tracks over the fused cross-track points");
  cmd->add_flag("!--union", a->merge.recompute_dense,
                "Merge the tracks' dense clouds as they are (default: run multi-view stereo again over the merged "
                "model when every track has a dense cloud)");
  cmd->add_flag("--keep-finer", a->merge.keep_finer_in_overlap,
                "Where tracks overlap, keep only the dense points of the track with the finer pixel footprint");
  cmd->add_option("--seed", a->opt.seed, "Random seed")->capture_default_str();
  cmd->callback([a] {
    a->opt.icp = !a->no_icp;
    std::vector<std::filesystem::path> ws(a->ws.begin(), a->ws.end());
    const auto report = align::RunAlignStage(ws, a->out, a->opt, a->merge);
    std::cout << fmt::format("align: {} tracks merged into {} (reference {})\n", ws.size(), a->out,
                             report.at("reference").get<std::string>());
    for (const auto& e : report.at("tree"))
      std::cout << fmt::format(
          "  {} -> {}: scale {:.6g}, {} 3D inliers, overlap {:.0f}%, residual RMS {:.4g} -> {:.4g}\n",
          e.at("moving").get<std::string>(), e.at("reference").get<std::string>(),
          e.at("similarity").at("scale").get<double>(), e.at("inliers_3d").get<size_t>(),
          100 * e.at("overlap_fraction").get<double>(), e.at("residual_rms_before").get<double>(),
          e.at("residual_rms_after").get<double>());
    if (report.contains("joint_bundle_adjustment")) {
      const auto& j = report.at("joint_bundle_adjustment");
      std::cout << fmt::format(
          "  joint bundle adjustment: {} of {} cross-track links fused, reprojection RMS {:.3f} -> {:.3f} px\n",
          j.at("links_fused").get<size_t>(), j.at("links").get<size_t>(),
          j.at("reprojection_rms_before_px").get<double>(), j.at("reprojection_rms_after_px").get<double>());
    }
    const auto& m = report.at("merged");
    const auto& d = report.at("dense");
    std::cout << fmt::format("  merged: {} images, {} points, {} dense points ({})\n", m.at("images").get<size_t>(),
                             m.at("points").get<size_t>(), d.value("points", size_t{0}),
                             d.value("method", std::string("none")));
  });
}

const RegisterCommand reg(820, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_align
