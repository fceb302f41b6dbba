#include "fmv3d/geo/georef.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <filesystem>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/frame_centres.h"
#include "fmv3d/geo/georef_gcp.h"
#include "fmv3d/geo/georef_pairs.h"
#include "fmv3d/geo/line_of_sight_check.h"
#include "fmv3d/geo/telemetry_model.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

Georef ReadGeoref(const core::Workspace& ws) {
  const fs::path p = ws.georef_json();
  if (!fs::exists(p)) throw Error(ws.name() + ": no geo/georef.json — run `fmv3d georef` first");
  const nlohmann::json j = core::ReadJson(p);
  try {
    Georef g;
    g.origin = {j.at("origin").at("lat").get<double>(), j.at("origin").at("lon").get<double>(),
                j.at("origin").at("alt").get<double>()};
    g.vertical_datum = j.value("vertical_datum", "");
    g.datum = ParseVerticalDatum(g.vertical_datum);
    const auto& s = j.at("similarity");
    g.sparse_to_enu.s = s.at("scale").get<double>();
    const auto q = s.at("rotation_wxyz").get<std::vector<double>>();
    const auto t = s.at("translation").get<std::vector<double>>();
    if (q.size() != 4 || t.size() != 3) throw Error("bad similarity");
    g.sparse_to_enu.q = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized();
    g.sparse_to_enu.t = Eigen::Vector3d(t[0], t[1], t[2]);
    g.utm.zone = j.at("utm").at("zone").get<int>();
    g.utm.north = j.at("utm").at("north").get<bool>();
    if (g.utm.zone < 1 || g.utm.zone > 60 || !(g.sparse_to_enu.s > 0)) throw Error("bad values");
    g.consistent_with_telemetry = j.value("consistent_with_telemetry", true);
    g.trusted = j.value("trusted", true);
    g.untrusted_reason = j.value("untrusted_reason", "");
    if (j.contains("expected_accuracy")) g.accuracy = GeorefAccuracy::FromJson(j["expected_accuracy"]);
    return g;
  } catch (const std::exception& e) {
    throw Error(p.string() + ": malformed georef (" + e.what() + ") — run `fmv3d georef` again");
  }
}

const char* RebuildTriggerName(RebuildTrigger t) {
  switch (t) {
    case RebuildTrigger::kNone:
      return "none";
    case RebuildTrigger::kForced:
      return "forced (--constrain always)";
    case RebuildTrigger::kTrackDoesNotFit:
      return "the track does not fit the model";
    case RebuildTrigger::kFrameCentresDisagree:
      return "the frame centres disagree with the model";
    case RebuildTrigger::kStraightTrackWithFrameCentres:
      return "a nearly straight track with frame centres";
  }
  return "";
}

RebuildTrigger WhyRebuild(const GeorefSolution& g, GeorefOptions::Constrain constrain) {
  if (constrain == GeorefOptions::Constrain::kNever) return RebuildTrigger::kNone;
  if (constrain == GeorefOptions::Constrain::kAlways) return RebuildTrigger::kForced;
  if (!g.consistent_with_telemetry()) return RebuildTrigger::kTrackDoesNotFit;
  // Frame centres that disagree with the model placed by the positions say its shape is wrong where its
  // trajectory alone cannot (a telephoto pass's image model bends its lines of sight, not its track).
  if (g.frame_centres.disagree()) return RebuildTrigger::kFrameCentresDisagree;
  // A nearly straight track leaves the image model free to bend about the track (a shallow dome or a roll that
  // grows along it) while every camera stays on the line; neither the positions nor one similarity can see that.
  // Frame centres that agree can: as priors on each optical axis they fix the shape (a straight pass: DSM 0.97%
  // → 0.27% of the building height).
  if (g.roll_source == RollSource::kGroundPlane && g.frame_centres.used())
    return RebuildTrigger::kStraightTrackWithFrameCentres;
  return RebuildTrigger::kNone;
}

bool RebuildMends(RebuildTrigger trigger, const GeorefSolution& image, const GeorefSolution& rebuilt, double image_px,
                  double rebuilt_px) {
  const bool explains_images = rebuilt_px <= 1.5 * image_px + 0.1;
  if (trigger == RebuildTrigger::kTrackDoesNotFit) return rebuilt.fit_fraction > image.fit_fraction;
  // A rebuild whose frame centres still disagree mends it too when it removes more of their disagreement than
  // the whole agreement band and explains the images as well: a telephoto pass with 49 keyframes, image model χ²
  // 3096 and surface 11.3 m, rebuilt χ² 39 and 1.2 m.
  const double chi2_image = image.frame_centres.chi2().value_or(0.0);
  const auto chi2_rebuilt = rebuilt.frame_centres.chi2();
  const bool sights_closer = trigger == RebuildTrigger::kFrameCentresDisagree && chi2_rebuilt &&
                             *chi2_rebuilt < chi2_image - kFrameCentreAgreementChi2 && explains_images;
  bool mended = (rebuilt.frame_centres.used() || sights_closer) && rebuilt.consistent_with_telemetry();
  if (trigger == RebuildTrigger::kStraightTrackWithFrameCentres) mended = mended && explains_images;
  return mended;
}

namespace {

// Empty when the georeference can be trusted, else why not.
std::string UntrustedReason(const GeorefSolution& g, const LineOfSightCheck& sight) {
  if (!g.consistent_with_telemetry())
    return fmt::format("only {:.0f}% of the telemetry fits the model's trajectory", 100 * g.fit_fraction);
  if (sight.verdict == LineOfSightCheck::Verdict::kDisagrees) return sight.Why();
  return "";
}

std::vector<Eigen::Vector3d> Points(const core::Reconstruction& rec) {
  std::vector<Eigen::Vector3d> pts;
  pts.reserve(rec.points.size());
  for (const auto& [id, p] : rec.points) pts.push_back(p.xyz);
  return pts;
}

// The chosen model and its georeference, with the rebuild's report.
struct Choice {
  const core::Reconstruction* model = nullptr;  // what WS/sparse must hold
  bool replaces_sparse = false;
  GeorefSolution solution;
  PairedTelemetry pairs;  // the model's
  nlohmann::json telemetry_constrained;
};

// Builds the telemetry-initialised model, georeferences it in memory and keeps it when it mends the image model.
Choice ChooseModel(const io::FramesIndex& index, const std::vector<telemetry::TelemetryTrack>* tracks,
                   const core::Reconstruction& image_model, const PairedTelemetry& pairs, GeorefSolution image,
                   RebuildTrigger trigger, const GeorefOptions& o, TelemetryModel* built) {
  Choice c{&image_model, false, std::move(image), pairs, {{"applied", false}}};
  if (trigger == RebuildTrigger::kNone) return c;
  const GeorefSolution& g = c.solution;
  spdlog::info(
      "georef: {:.0f}% of the telemetry fits the model's trajectory ({}); building the model again from "
      "the telemetry's cameras",
      100 * g.fit_fraction, RebuildTriggerName(trigger));
  core::Reconstruction image_enu = image_model;
  image_enu.Transform(g.sim);
  const LocalFrame frame(g.origin);
  std::optional<GeorefSolution> rebuilt;
  PairedTelemetry again;
  try {
    *built = BuildTelemetryModel(index, image_enu, pairs.keyframes, g.frame_centres.by_name, frame,
                                 {o.prior_sigma_m, o.attitude_sigma_deg});
    again = PairTelemetry(index, built->model, tracks, o.min_cameras, "georef");
    rebuilt = EstimateGeoref(again, Points(built->model), g.origin, g.origin_given, o);
  } catch (const Error& e) {
    spdlog::warn("{}; keeping the image-only model", e.what());
    c.telemetry_constrained = {{"applied", false}, {"why", e.what()}, {"trigger", RebuildTriggerName(trigger)}};
    return c;
  }
  nlohmann::json info = built->ToJson({o.prior_sigma_m, o.attitude_sigma_deg});
  info["trigger"] = RebuildTriggerName(trigger);
  const double image_px = ReprojectionRms(image_enu);
  info["reprojection_rms_px_image_only"] = image_px;
  info["frame_centres_chi2_image_only"] = g.frame_centres.chi2().value_or(0.0);
  if (const auto chi2 = rebuilt->frame_centres.chi2()) info["frame_centres_chi2"] = *chi2;
  const bool keep =
      trigger == RebuildTrigger::kForced || RebuildMends(trigger, g, *rebuilt, image_px, built->reprojection_rms_px);
  if (keep) {
    info["applied"] = true;
    info["fit_fraction_image_only"] = g.fit_fraction;
    c = Choice{&built->model, true, std::move(*rebuilt), std::move(again), std::move(info)};
    return c;
  }
  spdlog::warn(
      "georef: the telemetry-initialised model mends nothing ({:.0f}% of the track fits it, its frame "
      "centres {} (χ² {:.1f} against the image model's {:.1f}), reprojection {:.2f} px RMS against the "
      "image model's {:.2f}); keeping the image-only model",
      100 * rebuilt->fit_fraction, rebuilt->frame_centres.used() ? "agree" : "do not agree either",
      rebuilt->frame_centres.chi2().value_or(-1.0), g.frame_centres.chi2().value_or(0.0), built->reprojection_rms_px,
      image_px);
  info["applied"] = false;
  info["fit_fraction_telemetry_model"] = rebuilt->fit_fraction;
  c.telemetry_constrained = std::move(info);
  return c;
}

// The GCP georeference (georef_gcp.h): same outputs as the telemetry one.
nlohmann::json RunGcpGeoref(const core::Workspace& ws, const fs::path& gcp_file, const io::FramesIndex& index,
                            const core::Reconstruction& model, const GeorefOptions& o) {
  const io::FrameTable frames = io::FrameTableOf(index);
  const GcpList list = ReadGcpList(gcp_file, &frames);
  const GcpCrs crs(list.crs);
  GcpGeorefOptions go;
  go.origin = o.origin;
  go.adjust = o.gcp_adjust;
  GcpGeoref g = EstimateGcpGeoref(model, GroupGcps(list), crs, go);
  g.crs = list.crs;
  core::EnsureDirectory(ws.geo_dir());
  io::WriteColmapText(g.enu, ws.sparse_enu_dir());
  nlohmann::json j = g.ToJson();
  j["gcps"]["file"] = gcp_file.string();
  j["cameras"] = model.images.size();
  core::WriteJson(ws.georef_json(), j);
  if (g.adjustment.applied)
    spdlog::info(
        "georef: bundle adjustment with {} GCP clicks: their reprojection RMS {:.2f} → {:.2f} px, cameras moved up "
        "to {:.3f} m from the similarity's placement",
        g.adjustment.observations, g.adjustment.gcp_rms_px_before, g.adjustment.gcp_rms_px_after,
        g.adjustment.max_camera_shift_m);
  spdlog::info("georef: {} control points (RMS {:.3f} m), {} check points{}, scale {:.4f} → {}", g.control_used,
               g.control_rms_m, g.check_used,
               g.check_used ? fmt::format(" (RMS {:.3f} m, the independent accuracy)", g.check_rms_m) : "", g.sim.s,
               ws.georef_json().string());
  for (const auto& p : g.points)
    if (!p.triangulated_ok()) spdlog::warn("georef: GCP \"{}\" not used: {}", p.name, GcpStatusName(p.status));
  return j;
}

}  // namespace

nlohmann::json RunGeorefStage(const core::Workspace& ws, const GeorefOptions& o) {
  o.Check();
  if (!fs::exists(ws.frames_json())) throw Error(ws.name() + ": no frames/frames.json — run `fmv3d frames` first");
  if (!fs::exists(ws.sparse_dir() / "images.txt"))
    throw Error(ws.name() + ": no sparse/ model — run `fmv3d sparse` first");
  const io::FramesIndex index = io::ReadFramesIndex(ws.frames_json());
  const core::Reconstruction image_model = io::ReadColmapText(ws.sparse_dir());
  const fs::path manual_gcp = ws.manual_dir() / "gcp_list.txt";
  if (o.gcp_file || (o.use_gcps && fs::exists(manual_gcp)))
    return RunGcpGeoref(ws, o.gcp_file.value_or(manual_gcp), index, image_model, o);
  std::optional<std::vector<telemetry::TelemetryTrack>> tracks;
  if (o.use_track && fs::exists(ws.telemetry_json())) tracks = telemetry::ReadTelemetryTracks(ws.telemetry_json());
  const std::vector<telemetry::TelemetryTrack>* track_ptr = tracks ? &*tracks : nullptr;

  const PairedTelemetry pairs = PairTelemetry(index, image_model, track_ptr, o.min_cameras, ws.frames_json().string());
  const GeoPoint origin = o.origin ? *o.origin : TelemetryCentroid(pairs.fit());
  GeorefSolution image = EstimateGeoref(pairs, Points(image_model), origin, o.origin.has_value(), o);
  const RebuildTrigger trigger = WhyRebuild(image, o.constrain);
  TelemetryModel built;
  Choice choice = ChooseModel(index, track_ptr, image_model, pairs, std::move(image), trigger, o, &built);
  const GeorefSolution& g = choice.solution;

  core::EnsureDirectory(ws.geo_dir());
  if (choice.replaces_sparse) {
    io::WriteColmapText(image_model, ws.sparse_image_only_dir());
    io::WriteColmapText(*choice.model, ws.sparse_dir());
    choice.telemetry_constrained["image_only_model"] = ws.sparse_image_only_dir().string();
  }
  core::Reconstruction enu = *choice.model;
  enu.Transform(g.sim);
  io::WriteColmapText(enu, ws.sparse_enu_dir());
  nlohmann::json j = g.ToJson();
  j["telemetry_constrained"] = choice.telemetry_constrained;
  if (!g.consistent_with_telemetry())
    spdlog::warn(
        "georef: only {:.0f}% of the telemetry fits the model's trajectory: the reconstruction's shape "
        "disagrees with the flight (too little parallax?); georeferenced products are not reliable",
        100 * g.fit_fraction);
  LineOfSightOptions lo;
  lo.pointing_sigma_deg = o.attitude_sigma_deg;
  const LineOfSightCheck sight =
      CheckLinesOfSight(enu, choice.pairs.keyframes, g.datum, LocalFrame(g.origin), &g.accuracy, lo);
  j["line_of_sight"] = sight.ToJson();
  const std::string untrusted = UntrustedReason(g, sight);
  j["trusted"] = untrusted.empty();
  if (!untrusted.empty()) {
    j["untrusted_reason"] = untrusted;
    spdlog::warn("georef: the georeference cannot be trusted: {}", untrusted);
  } else if (sight.verdict == LineOfSightCheck::Verdict::kAgrees) {
    spdlog::info("georef: {}", sight.Why());
  }
  core::WriteJson(ws.georef_json(), j);
  size_t keyframe_inliers = 0;
  for (const auto& k : g.keyframes) keyframe_inliers += k.inlier;
  spdlog::info(
      "georef: fit on {} {} ({} inliers, σ {:.2f} m per axis, expected translation error {:.2f} m); "
      "{} of {} keyframes inliers, scale {:.4f} → {}",
      g.fit_pairs, g.use_track ? "telemetry packets" : "keyframes", g.fit_inliers, g.fit.sigma,
      g.expected_translation_error_m, keyframe_inliers, g.keyframes.size(), g.sim.s, ws.georef_json().string());
  return j;
}

}  // namespace fmv3d::geo
