// `fmv3d compare RECON.ply --cad MODEL.obj --length H -o OUTDIR`: distance of a reconstruction to its CAD
// model (align/compare.h) → OUTDIR/compare.json, histograms.png, top.png, side.png, compare.html, cad_error.ply
// (the CAD coloured by the error, align/error_mesh.h; the console shows it when OUTDIR is WS/report/compare).
#include <fmt/format.h>

#include <iostream>

#include "command.h"
#include "fmv3d/align/compare.h"

namespace fmv3d::app::cmd_compare {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("compare", "Distance of a reconstruction (PLY points or mesh) to a CAD model (OBJ)");
  cmd->footer(
      "Alignment: --transform (JSON {\"scale\": s, \"rotation\": [[3x3]], \"translation\": [x,y,z]} mapping the\n"
      "reconstruction into the CAD frame; WS/report/sparse_eval.json of `fmv3d evaluate-sparse` works too),\n"
      "else global registration (assumes both cover about the same\n"
      "extent); then scaled point-to-plane ICP unless --no-icp. Errors are fractions of --length H: X, Y, Z\n"
      "components of (point - closest CAD point) and the signed distance; completeness is the share of the\n"
      "CAD surface with a point within --threshold (restricted to the surface seen by >= 2 cameras with\n"
      "--cameras, a COLMAP model in the CAD frame). Points outside the CAD's box grown by --crop, and\n"
      "points lower than --ground-cut above the CAD's base (z up), are not measured.");
  struct Args {
    std::string recon, cad, out, transform, cameras, loss = "cauchy";
    align::CompareOptions opt;
    bool no_icp = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("RECON", a->recon, "Reconstruction PLY (points or mesh vertices)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--cad", a->cad, "CAD model (OBJ)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--length", a->opt.length, "Characteristic length H in CAD units (e.g. building height)")
      ->required()
      ->check(CLI::PositiveNumber);
  cmd->add_option("-o,--output", a->out, "Output folder")->required();
  cmd->add_option("--transform", a->transform, "Similarity JSON mapping RECON into the CAD frame")
      ->check(CLI::ExistingFile);
  cmd->add_option("--cameras", a->cameras, "COLMAP model in the CAD frame: completeness over the seen surface")
      ->check(CLI::ExistingDirectory);
  cmd->add_flag("--no-icp", a->no_icp, "Keep the coarse alignment (no ICP refinement)");
  cmd->add_option("--crop", a->opt.crop_margin, "Crop margin around the CAD's box, fraction of H")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--ground-cut", a->opt.ground_cut,
                  "Points lower than this above the CAD's lowest z are ground (not measured), fraction of H")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  cmd->add_option("--threshold", a->opt.completeness_threshold, "Completeness distance, fraction of H")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--spacing", a->opt.sample_spacing, "CAD surface sample spacing, fraction of H")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--min-views", a->opt.min_views, "Cameras that must see a CAD sample (with --cameras)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--trim", a->opt.icp_options.trim_fraction, "ICP: share of the closest pairs kept")
      ->check(CLI::Range(0.01, 1.0))
      ->capture_default_str();
  cmd->add_option("--loss", a->loss, "ICP robust loss: none | huber | cauchy")
      ->check(CLI::IsMember({"none", "huber", "cauchy"}))
      ->capture_default_str();
  cmd->add_flag("!--rigid", a->opt.icp_options.estimate_scale, "ICP: keep the scale of the coarse alignment");
  cmd->callback([a] {
    auto& o = a->opt;
    o.reconstruction = a->recon;
    o.cad = a->cad;
    o.output_dir = a->out;
    o.icp = !a->no_icp;
    o.icp_options.loss = align::ParseRobustLoss(a->loss);
    if (!a->transform.empty()) o.transform = align::ReadSim3Json(a->transform);
    if (!a->cameras.empty()) o.cameras = a->cameras;
    const auto r = align::CompareToCad(o);
    std::cout << fmt::format("compare: {} of {} points measured (alignment: {}{})\n", r.points_measured, r.points_total,
                             r.coarse, r.icp ? " + ICP" : "")
              << fmt::format("  {:<16} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}\n", "% of H", "mean", "std", "RMS",
                             "|e| 50%", "|e| 90%", "|e| 99%");
    const std::pair<const char*, const align::ErrorStats*> rows[] = {
        {"X", &r.x}, {"Y", &r.y}, {"Z", &r.z}, {"signed distance", &r.total}};
    for (const auto& [name, s] : rows)
      std::cout << fmt::format("  {:<16} {:>9.3f} {:>9.3f} {:>9.3f} {:>9.3f} {:>9.3f} {:>9.3f}\n", name, 100 * s->mean,
                               100 * s->std, 100 * s->rms, 100 * s->p50, 100 * s->p90, 100 * s->p99);
    std::cout << fmt::format("  completeness {:.1f}% of {} CAD samples{}\n", 100 * r.completeness, r.surface_samples,
                             r.completeness_seen_only ? " seen by >= 2 cameras" : "")
              << "  report: " << (std::filesystem::path(a->out) / "compare.html").string() << "\n";
  });
}

const RegisterCommand reg(850, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_compare
