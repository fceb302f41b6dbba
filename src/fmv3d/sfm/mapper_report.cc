#include "fmv3d/sfm/mapper_report.h"

#include <fmt/format.h>

#include <string>

#include "fmv3d/core/camera_json.h"

namespace fmv3d::sfm {

nlohmann::json ToJson(const TrackSummary& t) {
  nlohmann::json j = {{"union_find_tracks", t.union_find_tracks},
                      {"union_find_links", t.union_find_links},
                      {"union_find_conflicts_cut", t.union_find_conflicts_cut},
                      {"union_find_mean_length", t.union_find_mean_length},
                      {"union_find_mean_length_3_or_more_views", t.union_find_mean_length_3_or_more_views},
                      {"definition",
                       "mean track length = observations / points of the model (as COLMAP reports it); union_find: "
                       "tracks of all verified matches, a link putting two keypoints of one image in a track cut"}};
  if (!t.largest_model) return j;
  const TrackCoverage& c = *t.largest_model;
  j["model_points"] = c.points;
  j["model_observations"] = c.observations;
  j["model_mean_track_length"] = c.points ? static_cast<double>(c.observations) / c.points : 0.0;
  j["union_find_tracks_touched"] = c.tracks_touched;
  j["keypoints_of_touched_tracks"] = c.keypoints_of_touched_tracks;
  j["keypoints_of_touched_tracks_held"] = c.held_of_touched_tracks;
  j["touched_tracks_split_over_points"] = c.tracks_split;
  return j;
}

nlohmann::json ToJson(const std::vector<GuidedCompletionPass>& passes) {
  if (passes.empty()) return {{"run", false}};
  nlohmann::json out = nlohmann::json::array();
  for (const GuidedCompletionPass& p : passes) {
    const GuidedCompletionStats& s = p.stats;
    const GuidedCompletionOptions& o = p.options;
    nlohmann::json j = {{"run", true},
                        {"observations_before", p.observations_before},
                        {"points", s.points},
                        {"projections_in_image", s.projections},
                        {"with_free_keypoint_in_radius", s.candidates},
                        {"observations_added", s.accepted},
                        {"conflicts", s.conflicts},
                        {"ambiguous", s.ambiguous},
                        {"ratio", o.ratio},
                        {"radius_cap_px", o.max_error_px},
                        {"search_mass", o.search_mass},
                        {"keypoint_sigma_px", s.sigma_px},
                        {"median_search_radius_px", s.median_radius_px},
                        {"decoy_searches_with_keypoint", s.decoys},
                        {"false_accept_rate", o.false_accept_rate},
                        {"expected_false_additions_at_most", o.false_accept_rate * s.candidates},
                        {"descriptor_bound_squared", s.descriptor_bound},
                        {"member_nearest_distance_median_squared", s.member_median},
                        {"seconds", p.seconds}};
    if (p.removed_after_adjustment) j["removed_after_adjustment"] = *p.removed_after_adjustment;
    out.push_back(std::move(j));
  }
  return out;
}

nlohmann::json ToJson(const MapperTimings& t) {
  return {{"initial_pair", t.init}, {"absolute_pose", t.registration}, {"triangulation", t.triangulation},
          {"local_ba", t.local_ba}, {"global_ba", t.global_ba},        {"filtering", t.filtering},
          {"total", t.total}};
}

nlohmann::json ToJson(const MapperStats& s) {
  return {{"correspondences", s.correspondences},
          {"tracks", ToJson(s.tracks)},
          {"guided_completion", ToJson(s.guided_completion)},
          {"invalid_matches_skipped", s.invalid_matches_skipped},
          {"models", s.models},
          {"relocalised_images", s.relocalised_images},
          {"seconds", ToJson(s.seconds)}};
}

nlohmann::json ToJson(const NestedModelTestResult& r) {
  nlohmann::json params = nlohmann::json::object();
  for (size_t i = 0; i < r.parameters.size(); ++i) {
    nlohmann::json p = {{"held", r.held_values[i]}, {"free_fit", r.freed_values[i]}};
    if (i < r.sigmas.size()) p["posterior_sigma"] = r.sigmas[i];
    params[IntrinsicName(r.parameters[i])] = p;
  }
  return {{"group", ToString(r.group)},
          {"decision", ToString(r.decision)},
          {"freed", r.freed_decision()},
          {"delta_chi2", r.delta_chi2},
          {"delta_chi2_needed", r.threshold},
          {"criterion",
           std::string(r.fixed_threshold ? "free when delta_chi2 exceeds a fixed threshold"
                                         : "free when delta_chi2 > k ln(n) (BIC; k extra parameters, "
                                           "n residuals)") +
               " and the squared shift of its parameters exceeds their posterior variance (BA covariance), summed over "
               "the group"},
          {"extra_parameters", r.num_parameters},
          {"observations", r.num_observations},
          {"observations_outside_gaussian_core", r.observations_left_out},
          {"core_sigma_px", r.core_sigma_px},
          {"corner_displacement_1sigma_px", r.max_sigma_px},
          {"rms_held_px", r.rms_held_px},
          {"rms_free_px", r.rms_freed_px},
          {"parameters", params}};
}

nlohmann::json ToJson(const IntrinsicsPosterior& p) {
  nlohmann::json params = nlohmann::json::object(), warnings = nlohmann::json::array();
  for (const auto& u : p.parameters) {
    nlohmann::json j = {{"value", u.value}};
    if (p.determined) {
      j["posterior_sigma"] = u.sigma;
      j["corner_displacement_1sigma_px"] = u.corner_sigma_px;
      j["weakly_determined"] = u.weak;
    }
    params[IntrinsicName(u.parameter)] = j;
    if (u.weak)
      warnings.push_back(
          fmt::format("{} is weakly determined by these images: ±{:.3g} (1σ), {:.2f} px at the image "
                      "corner",
                      IntrinsicName(u.parameter), u.sigma, u.corner_sigma_px));
  }
  if (!p.determined && !p.parameters.empty())
    warnings.push_back("the free intrinsics are not all determined by these images (the covariance is rank-deficient)");
  nlohmann::json j = {{"camera_id", p.camera_id},
                      {"determined", p.determined},
                      {"weak_above_corner_px", p.weak_corner_px},
                      {"parameters", params},
                      {"warnings", warnings}};
  if (p.determined && !p.parameters.empty()) {
    nlohmann::json corr = nlohmann::json::object(), dir = nlohmann::json::object();
    for (size_t a = 0; a < p.parameters.size(); ++a) {
      dir[IntrinsicName(p.parameters[a].parameter)] = p.weakest_direction[a];
      for (size_t b = a + 1; b < p.parameters.size(); ++b)
        corr[fmt::format("{},{}", IntrinsicName(p.parameters[a].parameter), IntrinsicName(p.parameters[b].parameter))] =
            p.correlation(a, b);
    }
    j["correlation"] = corr;
    j["least_determined_combination"] = {{"corner_displacement_1sigma_px", p.weakest_corner_sigma_px},
                                         {"direction_in_corner_px", dir}};
  }
  return j;
}

nlohmann::json ToJson(const FocalDecision& d) {
  nlohmann::json j;  // null: no decision recorded
  if (d.kind == FocalDecisionKind::kKnown) {
    j = {{"decision", FocalDecisionName(d.kind)}, {"focal_px", d.known_focal_px}};
  } else if (d.kind == FocalDecisionKind::kRestart) {
    j = {{"decision", FocalDecisionName(d.kind)}, {"guess_px", d.guess_px}, {"focal_px", d.two_view_focal_px}};
  } else if (d.kind != FocalDecisionKind::kNone) {
    j = {{"guess_px", d.guess_px},
         {"pairs", d.pairs},
         {"two_view_focal_px", d.two_view_focal_px},
         {"decision", FocalDecisionName(d.kind)},
         {"pinhole_best_px2", d.pinhole_best_px2},
         {"division_best_px2", d.division_best_px2},
         {"division_excess_of_half_diagonal", d.division_excess_of_half_diagonal},
         {"division_kappa", d.division_kappa},
         {"initial_k1", d.initial_k1},
         {"initial_k2", d.initial_k2},
         {"candidates", d.candidates},
         {"seconds", d.seconds},
         {"division_seconds", d.division_seconds}};
  }
  if (const auto& z = d.dolly_zoom)
    j["dolly_zoom"] = {{"images", z->images},     {"factor", z->factor},
                       {"focal_px", z->focal_px}, {"shortest_factor", z->shortest_factor},
                       {"released", z->released}, {"seconds", z->seconds}};
  if (const auto& r = d.restart)
    j["restart"] = {{"first_start_px", r->first_start_px},
                    {"first_final_px", r->first_final_px},
                    {"change", r->change},
                    {"first_images", r->first_images},
                    {"first_reprojection_px", r->first_reprojection_px},
                    {"early", r->early},
                    {"kept", r->kept ? "second" : "first"},
                    {"seconds", r->seconds}};
  return j;
}

namespace {

// The report's per-model section: size, accuracy, cameras, self-calibration tests and how the focal was decided.
nlohmann::json ModelReport(const core::Reconstruction& rec, const std::vector<NestedModelTestResult>* calibration,
                           const std::vector<IntrinsicsPosterior>* posterior, const nlohmann::json& focal_decision) {
  nlohmann::json tests = nlohmann::json::array(), uncertainty = nlohmann::json::array();
  if (calibration)
    for (const auto& t : *calibration) tests.push_back(ToJson(t));
  if (posterior)
    for (const auto& p : *posterior) uncertainty.push_back(ToJson(p));
  nlohmann::json cams = nlohmann::json::array();
  for (const auto& [id, c] : rec.cameras) {
    nlohmann::json cam = core::IntrinsicsToJson(c);
    cam["id"] = id;
    cams.push_back(cam);
  }
  return {{"registered_images", rec.images.size()},
          {"points", rec.points.size()},
          {"mean_track_length", rec.MeanTrackLength()},
          {"mean_reprojection_error_px", rec.MeanReprojectionError()},
          {"cameras", cams},
          {"self_calibration", tests},
          {"intrinsics_posterior", uncertainty},
          {"focal_decision", focal_decision}};
}

}  // namespace

nlohmann::json SparseReport(const MapperInput& input, const MapperResult& result) {
  nlohmann::json report;
  report["total_images"] = input.images.size();
  report["models"] = nlohmann::json::array();
  for (size_t m = 0; m < result.models.size(); ++m)
    report["models"].push_back(
        ModelReport(result.models[m], m < result.self_calibration.size() ? &result.self_calibration[m] : nullptr,
                    m < result.intrinsics_posterior.size() ? &result.intrinsics_posterior[m] : nullptr,
                    m < result.focal_decision.size() ? ToJson(result.focal_decision[m]) : nlohmann::json::object()));
  const core::Reconstruction* best = result.models.empty() ? nullptr : &result.models[0];
  report["registered_images"] = best ? best->images.size() : 0;
  report["points"] = best ? best->points.size() : 0;
  report["mean_track_length"] = best ? best->MeanTrackLength() : 0.0;
  report["mean_reprojection_error_px"] = best ? best->MeanReprojectionError() : 0.0;
  report["self_calibration"] = best ? report["models"][0]["self_calibration"] : nlohmann::json::array();
  report["intrinsics_posterior"] = best ? report["models"][0]["intrinsics_posterior"] : nlohmann::json::array();
  report["focal_decision"] = best ? report["models"][0]["focal_decision"] : nlohmann::json::object();
  nlohmann::json left = nlohmann::json::array();
  for (const auto& [id, why] : result.left_out) left.push_back({{"image", input.images[id - 1].name}, {"reason", why}});
  report["left_out"] = left;
  report["mapper"] = ToJson(result.stats);
  return report;
}

}  // namespace fmv3d::sfm
