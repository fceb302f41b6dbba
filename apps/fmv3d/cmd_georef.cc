// `fmv3d georef WS [--origin LAT,LON,ALT] [--gcp FILE | --no-gcp]`: with ground control points
// (WS/manual/gcp_list.txt or --gcp, geo/georef_gcp.h) the similarity from the triangulated GCPs to their
// coordinates; otherwise the robust similarity from the sparse model's camera centres to the frames' telemetry
// positions → WS/geo/sparse_enu/ (COLMAP text model in local ENU metres) and
// WS/geo/georef.json (origin, similarity, residuals, UTM zone / EPSG, PROJ pipelines). With frames/telemetry.json
// every packet is fitted against the model trajectory at its time (see geo/georef.h).
#include <cstdio>
#include <sstream>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/geo/georef.h"

namespace fmv3d::app::cmd_georef {
namespace {

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "georef", "Georeference the sparse model with GCPs or telemetry (WS/geo/georef.json, sparse_enu/)");
  struct Args {
    std::string ws, origin, constrain = "auto", gcp;
    geo::GeorefOptions opt;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS", a->ws, "Workspace folder (with frames/frames.json carrying telemetry, and sparse/)")
      ->required();
  cmd->add_option("--origin", a->origin, "Local ENU origin LAT,LON,ALT (default: centroid of the telemetry positions)");
  cmd->add_option("--seed", a->opt.seed, "Random seed of the robust fit")->capture_default_str();
  auto* kf_only = cmd->add_flag(
      "--keyframes-only", "Fit only the registered keyframes' telemetry, not every packet of frames/telemetry.json");
  auto* no_fc = cmd->add_flag("--no-frame-centres",
                              "Fit the positions (and attitudes) only; ignore the frame centres at their slant range");
  cmd->add_option("--constrain", a->constrain,
                  "Build the model again from the telemetry's cameras and replace WS/sparse when it fits the "
                  "flight better (the image-only model goes to WS/geo/sparse_image_only/): auto = when the "
                  "model's trajectory disagrees with the telemetry")
      ->check(CLI::IsMember({"auto", "always", "never"}))
      ->capture_default_str();
  cmd->add_option("--prior-sigma", a->opt.prior_sigma_m, "Telemetry position accuracy per axis, metres (priors' sigma)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--gcp", a->gcp,
                  "Ground control points (OpenDroneMap gcp_list.txt) instead of "
                  "WS/manual/gcp_list.txt; GCPs outrank telemetry");
  auto* no_gcp = cmd->add_flag("--no-gcp", "Ignore WS/manual/gcp_list.txt (georeference from telemetry)");
  auto* no_adjust = cmd->add_flag("--gcp-no-adjust",
                                  "GCPs: the similarity from the triangulated GCPs only, without the bundle adjustment "
                                  "that holds the control points at their coordinates");
  cmd->callback([a, kf_only, no_fc, no_gcp, no_adjust] {
    a->opt.gcp_adjust = no_adjust->count() == 0;
    if (!a->gcp.empty()) a->opt.gcp_file = a->gcp;
    a->opt.use_gcps = no_gcp->count() == 0;
    a->opt.use_track = kf_only->count() == 0;
    a->opt.use_frame_centres = no_fc->count() == 0;
    a->opt.constrain = a->constrain == "always"  ? geo::GeorefOptions::Constrain::kAlways
                       : a->constrain == "never" ? geo::GeorefOptions::Constrain::kNever
                                                 : geo::GeorefOptions::Constrain::kAuto;
    if (!a->origin.empty()) {
      geo::GeoPoint g;
      char extra = 0;
      if (std::sscanf(a->origin.c_str(), "%lf,%lf,%lf%c", &g.lat, &g.lon, &g.alt, &extra) != 3)
        throw CLI::ValidationError("--origin", "expected LAT,LON,ALT, e.g. 38.16,-77.35,60");
      a->opt.origin = g;
    }
    const auto j = geo::RunGeorefStage(a->ws, a->opt);
    if (j.value("source", "") == "gcp") {
      const auto& g = j["gcps"];
      std::printf("georef: %d GCPs fitted, residual RMS %.3f m; %d check points%s, scale %.5f, %s (EPSG:%d)\n",
                  g["control_points_used"].get<int>(), g["rms_m"].get<double>(), g["check_points_used"].get<int>(),
                  g["check_rms_m"].is_number()
                      ? (", RMS " + std::to_string(g["check_rms_m"].get<double>()) + " m").c_str()
                      : "",
                  j["similarity"]["scale"].get<double>(), j["utm"]["name"].get<std::string>().c_str(),
                  j["utm"]["epsg"].get<int>());
      return;
    }
    std::printf(
        "georef: fit on %d %s, %d/%d keyframes inliers, residual RMS %.3f m, expected translation error "
        "%.2f m, scale %.5f, %s (EPSG:%d)\n",
        j["fit"]["inliers"].get<int>(), j["fit"]["used"].get<bool>() ? "telemetry packets" : "keyframes",
        j["inliers"].get<int>(), j["cameras"].get<int>(), j["residuals"]["rms_m"].get<double>(),
        j["expected_translation_error_m"].get<double>(), j["similarity"]["scale"].get<double>(),
        j["utm"]["name"].get<std::string>().c_str(), j["utm"]["epsg"].get<int>());
    if (j.contains("telemetry_constrained") && j["telemetry_constrained"].value("applied", false))
      std::printf(
          "georef: model built again from the telemetry (fit %.0f%% → %.0f%% of the packets); WS/sparse "
          "replaced, run the later stages again\n",
          100 * j["telemetry_constrained"]["fit_fraction_image_only"].get<double>(),
          100 * j["fit_fraction"].get<double>());
  });
}

const RegisterCommand reg(700, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_georef
