#include "fmv3d/sfm/incremental_mapper.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/sfm/model_builder.h"
#include "fmv3d/sfm/track_builder.h"

namespace fmv3d::sfm {

void MapperOptions::Check() const {
  if (init_min_inliers < 8) throw Error("mapper: init_min_inliers must be ≥ 8");
  if (!(init_min_tri_angle_deg > 0)) throw Error("mapper: init_min_tri_angle_deg must be > 0");
  if (!(abs_pose_max_error_px > 0)) throw Error("mapper: abs_pose_max_error_px must be > 0");
  if (abs_pose_min_inliers < 4) throw Error("mapper: abs_pose_min_inliers must be ≥ 4");
  if (!(tri_max_error_px > 0) || !(filter_max_error_px > 0)) throw Error("mapper: error thresholds must be > 0");
  if (tri_min_angle_deg < 0 || filter_min_angle_deg < 0) throw Error("mapper: angles must be ≥ 0");
  if (local_ba_num_images < 1) throw Error("mapper: local_ba_num_images must be ≥ 1");
  if (local_ba_max_iterations < 1 || global_ba_max_iterations < 1 || final_ba_max_iterations < 1)
    throw Error("mapper: BA iteration limits must be ≥ 1");
  if (!(final_ba_function_tolerance > 0)) throw Error("mapper: final_ba_function_tolerance must be > 0");
  if (!(global_ba_growth_ratio > 1)) throw Error("mapper: global_ba_growth_ratio must be > 1");
  if (min_model_size < 2) throw Error("mapper: min_model_size must be ≥ 2");
  if (max_models < 1) throw Error("mapper: max_models must be ≥ 1");
  if (focal_scan_pairs < 1) throw Error("mapper: focal_scan_pairs must be ≥ 1");
  if (!(narrow_field_max_radius >= 0)) throw Error("mapper: narrow_field_max_radius must be ≥ 0");
  if (!(guided_completion_false_accept_rate > 0 && guided_completion_false_accept_rate < 1))
    throw Error("mapper: guided_completion_false_accept_rate must be in (0, 1)");
  if (!(self_calibration_min_delta_chi2 >= 0)) throw Error("mapper: self_calibration_min_delta_chi2 must be ≥ 0");
  if (!(focal_restart_min_change >= 0)) throw Error("mapper: focal_restart_min_change must be ≥ 0");
  if (focal_restart_min_images < 2) throw Error("mapper: focal_restart_min_images must be ≥ 2");
  if (!(weak_intrinsic_corner_px > 0)) throw Error("mapper: weak_intrinsic_corner_px must be > 0");
}

namespace {

TrackSummary SummariseTracks(const MapperInput& input, const std::map<uint32_t, size_t>& num_kp,
                             const std::vector<core::Reconstruction>& models) {
  const TrackSet tracks = BuildTracks(num_kp, input.pairs);
  TrackSummary t;
  t.union_find_tracks = tracks.tracks.size();
  t.union_find_links = tracks.num_links;
  t.union_find_conflicts_cut = tracks.num_conflicts;
  t.union_find_mean_length = tracks.MeanLength();
  t.union_find_mean_length_3_or_more_views = tracks.MeanLengthMultiView();
  if (!models.empty()) t.largest_model = MeasureTrackCoverage(tracks, models[0]);
  return t;
}

// The first model's growth stopped by ModelBuilder::StopWhenFocalMoves: where its focal went.
struct EarlyStop {
  mapper::ModelBuilder::FocalStop focal;
  size_t images = 0;
  double reprojection_px = 0;
};

// One mapping of every image: models grown until the pool is used up. focal_start: cameras started at that focal
// (ModelBuilder::StartFocalAt). With early set, the first model's growth stops once its guessed focal moved by more
// than options.focal_restart_min_change; the mapping then ends there with *early set (no models returned).
MapperResult MapOnce(const MapperInput& input, const MapperOptions& options,
                     const std::map<uint32_t, double>& focal_start, std::optional<EarlyStop>* early) {
  using mapper::Clock;
  using mapper::Seconds;
  const auto start = Clock::now();
  MapperResult result;
  std::map<uint32_t, const MapperImage*> images;
  std::map<uint32_t, size_t> num_kp;
  for (const auto& im : input.images) {
    if (!input.cameras.count(im.camera_id))
      throw Error("mapper: image " + im.name + " refers to unknown camera " + std::to_string(im.camera_id));
    input.cameras.at(im.camera_id).camera.Validate();
    if (images.count(im.id)) throw Error("mapper: duplicate image id " + std::to_string(im.id));
    images[im.id] = &im;
    num_kp[im.id] = im.keypoints.size();
  }
  const CorrespondenceGraph graph(num_kp, input.pairs);
  std::map<uint32_t, int> pair_count;
  for (const auto& p : input.pairs)
    if (images.count(p.image_id1) && images.count(p.image_id2) && !p.inliers.empty()) {
      ++pair_count[p.image_id1];
      ++pair_count[p.image_id2];
    }
  std::set<uint32_t> pool;
  std::map<uint32_t, std::string> reasons;
  for (const auto& [id, im] : images) {
    if (pair_count[id] > 0)
      pool.insert(id);
    else
      reasons[id] = im->keypoints.empty() ? "no features (blank or textureless frame)"
                                          : "no verified matches with any other image";
  }
  spdlog::info("mapper: {} images, {} verified pairs, {} correspondences ({} invalid skipped)", images.size(),
               input.pairs.size(), graph.NumCorrespondences(), graph.NumSkipped());

  MapperTimings timings;
  std::vector<std::map<uint32_t, std::string>> model_fail;
  std::vector<std::vector<GuidedCompletionPass>> guided;  // per model, in the order built
  std::vector<GuidedCompletionPass> guided_largest;
  int relocalised = 0;
  while (static_cast<int>(pool.size()) >= options.min_model_size &&
         static_cast<int>(result.models.size()) < options.max_models) {
    mapper::ModelBuilder builder(input, images, graph, options, pool, &timings);
    builder.StartFocalAt(focal_start);
    if (early && result.models.empty())
      builder.StopWhenFocalMoves(options.focal_restart_min_change, options.focal_restart_min_images);
    if (!builder.Initialize()) break;
    builder.Grow();
    if (const auto& stop = builder.focal_stop()) {
      *early = EarlyStop{*stop, builder.rec().images.size(), builder.rec().MeanReprojectionError()};
      result.stats.seconds = timings;
      result.stats.seconds.total = Seconds(start);
      return result;
    }
    relocalised += builder.num_relocalised();
    auto& rec = builder.rec();
    auto calibration = builder.self_calibration();
    for (const auto& [id, im] : rec.images) pool.erase(id);
    for (const auto& [id, why] : builder.fail_reasons())
      if (!reasons.count(id)) reasons[id] = why;
    if (static_cast<int>(rec.images.size()) < options.min_model_size) continue;
    spdlog::info("model {}: {} images, {} points", result.models.size(), rec.images.size(), rec.points.size());
    result.models.push_back(std::move(rec));
    result.self_calibration.push_back(std::move(calibration));
    result.intrinsics_posterior.push_back(builder.intrinsics_posterior());
    result.focal_decision.push_back(builder.focal_decision());
    guided.push_back(builder.guided_completion());
  }
  {  // largest first, each model with its self-calibration tests
    std::vector<size_t> order(result.models.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
      return result.models[a].images.size() > result.models[b].images.size();
    });
    if (!order.empty()) guided_largest = guided[order[0]];
    MapperResult sorted;
    for (size_t i : order) {
      sorted.models.push_back(std::move(result.models[i]));
      sorted.self_calibration.push_back(std::move(result.self_calibration[i]));
      sorted.intrinsics_posterior.push_back(std::move(result.intrinsics_posterior[i]));
      sorted.focal_decision.push_back(result.focal_decision[i]);
    }
    result.models = std::move(sorted.models);
    result.self_calibration = std::move(sorted.self_calibration);
    result.intrinsics_posterior = std::move(sorted.intrinsics_posterior);
    result.focal_decision = std::move(sorted.focal_decision);
  }
  for (size_t m = 0; m < result.models.size(); ++m)
    for (const auto& [id, im] : result.models[m].images) {
      if (m == 0)
        reasons.erase(id);
      else
        reasons[id] = "registered in disconnected model " + std::to_string(m) + " (" +
                      std::to_string(result.models[m].images.size()) + " images)";
    }
  for (uint32_t id : pool)
    if (!reasons.count(id)) reasons[id] = "no initial pair or connection to a model";
  for (const auto& [id, im] : images)
    if (!(result.models.size() && result.models[0].images.count(id)) && !reasons.count(id))
      reasons[id] = "not registered";
  result.left_out = reasons;
  MapperStats& st = result.stats;
  st.correspondences = graph.NumCorrespondences();
  st.invalid_matches_skipped = graph.NumSkipped();
  st.models = result.models.size();
  st.relocalised_images = relocalised;
  st.tracks = SummariseTracks(input, num_kp, result.models);
  st.guided_completion = std::move(guided_largest);
  st.seconds = timings;
  st.seconds.total = Seconds(start);
  return result;
}

// The largest model's guessed cameras whose focal its adjustments moved by more than min_change from where the
// mapping started it: camera id → the refined focal; *restart gets the largest move. Empty when the focal was
// stated, or found with a wide lens's distortion (that start is the scan's lens as well as its focal).
std::map<uint32_t, double> FocalsToRestartFrom(const MapperInput& input, const MapperResult& r, double min_change,
                                               FocalRestart* restart) {
  if (r.models.empty() || r.focal_decision.empty()) return {};
  const FocalDecision& d = r.focal_decision[0];
  if (!FocalMayRestart(d.kind)) return {};
  if (!(d.guess_px > 0)) return {};
  // The scans scale every guessed camera of the model alike (ModelBuilder::TryInitialPair).
  const double scale = (d.dolly_zoom ? d.dolly_zoom->focal_px : d.two_view_focal_px) / d.guess_px;
  std::map<uint32_t, double> out;
  for (const auto& [cid, cam] : r.models[0].cameras) {
    const auto it = input.cameras.find(cid);
    if (it == input.cameras.end() || it->second.focal_known) continue;
    const double start = scale * it->second.camera.f;
    const double moved = std::abs(cam.f / start - 1);
    if (moved > restart->change) {
      restart->change = moved;
      restart->first_start_px = start;
      restart->first_final_px = cam.f;
    }
    out[cid] = cam.f;
  }
  if (restart->change <= min_change) return {};
  return out;
}

}  // namespace

MapperResult RunIncrementalMapper(const MapperInput& input, const MapperOptions& options) {
  options.Check();
  const auto start = mapper::Clock::now();
  const bool restarts = options.focal_restart_min_change > 0;
  std::optional<EarlyStop> early;
  MapperResult first = MapOnce(input, options, {}, restarts ? &early : nullptr);
  if (!restarts) return first;
  FocalRestart restart;
  std::map<uint32_t, double> focal;
  if (early) {
    focal = early->focal.focal_px;
    restart.first_start_px = early->focal.start_px;
    restart.first_final_px = early->focal.final_px;
    restart.change = early->focal.change;
    restart.first_images = early->images;
    restart.first_reprojection_px = early->reprojection_px;
    restart.early = true;
  } else {
    focal = FocalsToRestartFrom(input, first, options.focal_restart_min_change, &restart);
    if (focal.empty()) return first;
    const core::Reconstruction& m = first.models[0];
    restart.first_images = m.images.size();
    restart.first_reprojection_px = m.MeanReprojectionError();
  }
  spdlog::info(
      "mapper: the focal moved {:.1f}% from its start ({:.1f} → {:.1f} px) while the model grew to {} images: "
      "mapping again from {:.1f} px",
      100 * restart.change, restart.first_start_px, restart.first_final_px, restart.first_images,
      restart.first_final_px);
  const auto second_start = mapper::Clock::now();
  MapperResult second = MapOnce(input, options, focal, nullptr);
  restart.seconds = mapper::Seconds(second_start);
  const size_t second_images = second.models.empty() ? 0 : second.models[0].images.size();
  // An early stop left no complete first model to compare with.
  restart.kept = early || second_images >= restart.first_images;
  // A guard (the same images and matches map again): a single full mapping then.
  if (early && second.models.empty()) return MapOnce(input, options, {}, nullptr);
  MapperResult& kept = restart.kept ? second : first;
  spdlog::info("mapper: second mapping {} images (first {}), focal {:.1f} px: {} kept", second_images,
               restart.first_images, second.models.empty() ? 0.0 : second.models[0].cameras.begin()->second.f,
               restart.kept ? "second" : "first");
  kept.focal_decision[0].restart = restart;
  // The report's per-part seconds cover both mappings, as its total does.
  const MapperTimings& other = restart.kept ? first.stats.seconds : second.stats.seconds;
  MapperTimings& t = kept.stats.seconds;
  t.init += other.init;
  t.registration += other.registration;
  t.triangulation += other.triangulation;
  t.local_ba += other.local_ba;
  t.global_ba += other.global_ba;
  t.filtering += other.filtering;
  t.total = mapper::Seconds(start);
  return kept;
}

}  // namespace fmv3d::sfm
