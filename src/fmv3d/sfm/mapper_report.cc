#include "fmv3d/sfm/mapper_report.h"

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

}  // namespace fmv3d::sfm
