#include "fmv3d/features/match_stage.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/spatial_pairs.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

PairGeometry ToPairGeometry(geometry::TwoViewClass c) {
  switch (c) {
    case geometry::TwoViewClass::kCalibrated:
      return PairGeometry::kCalibrated;
    case geometry::TwoViewClass::kUncalibrated:
      return PairGeometry::kUncalibrated;
    case geometry::TwoViewClass::kPlanarOrRotation:
      return PairGeometry::kPlanarOrRotation;
    default:
      return PairGeometry::kUndefined;
  }
}

const char* GeometryName(PairGeometry g) {
  switch (g) {
    case PairGeometry::kCalibrated:
      return "calibrated";
    case PairGeometry::kUncalibrated:
      return "uncalibrated";
    case PairGeometry::kPlanarOrRotation:
      return "planar_or_rotation";
    default:
      return "undefined";
  }
}

// Float descriptors + kd-trees per image, created on first use and released once every pair that needs the
// image is done, so sequential matching of long videos keeps only a sliding window in memory.
class DescriptorCache {
 public:
  DescriptorCache(const std::vector<FeatureSet>& features, const std::vector<ImagePair>& pairs)
      : features_(features), entries_(features.size()), remaining_(features.size()) {
    for (const auto& p : pairs) {
      ++remaining_[p.first];
      ++remaining_[p.second];
    }
  }
  std::shared_ptr<ImageDescriptors> Get(uint32_t i) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!entries_[i]) entries_[i] = std::make_shared<ImageDescriptors>(features_[i].descriptors, i + 1);
    return entries_[i];
  }
  void Done(uint32_t i) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (--remaining_[i] == 0) entries_[i].reset();
  }

 private:
  const std::vector<FeatureSet>& features_;
  std::mutex mutex_;
  std::vector<std::shared_ptr<ImageDescriptors>> entries_;
  std::vector<int> remaining_;
};

}  // namespace

MatchStageStats RunMatchStage(const core::Workspace& ws, const MatchStageOptions& options) {
  options.Check();
  const auto t_start = Clock::now();
  MatchStageStats stats;
  const fs::path frames_json = ws.frames_json();
  const fs::path features_dir = ws.features_dir(), matches_dir = ws.matches_dir();
  const auto index = io::ReadFramesIndex(frames_json);
  const size_t n = index.frames.size();
  stats.images = n;

  // --- Load features (parallel) and check them against the index.
  std::vector<FeatureSet> features(n);
  std::vector<std::string> errors(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    try {
      const fs::path p = FeaturePath(features_dir, index.frames[i].name);
      if (!fs::exists(p)) throw Error(p.string() + " is missing; run `fmv3d features " + ws.name() + "` first");
      features[i] = ReadFeatures(p);
      if (features[i].image_name != index.frames[i].name)
        throw Error(p.string() + ": holds features of '" + features[i].image_name + "', not '" + index.frames[i].name +
                    "' (re-run `fmv3d features --force`)");
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  });
  for (const auto& e : errors)
    if (!e.empty()) throw Error(e);
  std::vector<const core::Camera*> cameras(n);
  std::vector<bool> trusted(n);
  for (size_t i = 0; i < n; ++i) {
    const auto* prior = index.FindCamera(index.frames[i].camera_id);
    if (!prior)
      throw Error(frames_json.string() + ": frame '" + index.frames[i].name + "' refers to camera " +
                  std::to_string(index.frames[i].camera_id) + ", which is not in \"cameras\"");
    cameras[i] = &prior->camera;
    if (features[i].width != prior->camera.width || features[i].height != prior->camera.height)
      throw Error(frames_json.string() + ": frame '" + index.frames[i].name + "' is " +
                  std::to_string(features[i].width) + "x" + std::to_string(features[i].height) + " but camera " +
                  std::to_string(prior->camera.id) + " is " + std::to_string(prior->camera.width) + "x" +
                  std::to_string(prior->camera.height) + " (stale features? re-run `fmv3d features --force`)");
    trusted[i] = !prior->prior_source.empty() && prior->prior_source != "guess";
  }
  stats.seconds_load = Since(t_start);

  // --- Pairs.
  const auto t_pairs = Clock::now();
  std::vector<const Descriptors*> descs(n);
  for (size_t i = 0; i < n; ++i) descs[i] = &features[i].descriptors;
  PairMode mode = PairMode::kAuto;
  PairOptions pair_options = options.pairs;
  std::vector<Footprint> footprints;
  if (pair_options.mode == PairMode::kSpatial || pair_options.mode == PairMode::kAuto)
    footprints = FootprintsFromTelemetry(index);
  if (pair_options.mode == PairMode::kAuto && PreferSpatialPairs(index, footprints, pair_options)) {
    pair_options.mode = PairMode::kSpatial;
    spdlog::info("match: {} photos with GPS: pairs by overlapping ground footprints", n);
  }
  const auto pairs = SelectPairs(descs, pair_options, &mode, &stats.loop_closure_pairs, &footprints);
  stats.pairs_tried = pairs.size();
  stats.seconds_pairs = Since(t_pairs);
  spdlog::info("match: {} images, {} pairs ({}{})", n, pairs.size(), PairModeName(mode),
               mode == PairMode::kSequential
                   ? ", " + std::to_string(stats.loop_closure_pairs) + " loop-closure candidates"
                   : std::string());

  // --- Match + verify every pair in parallel. OpenCV's own threads stay off (parallelism is over pairs).
  const int cv_threads = cv::getNumThreads();
  cv::setNumThreads(1);
  DescriptorCache cache(features, pairs);
  std::vector<VerifiedPair> results(pairs.size());
  std::vector<char> verified(pairs.size(), 0);
  std::atomic<int64_t> ns_match{0}, ns_verify{0};
  core::Progress progress("match", pairs.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pairs.size(), 1), [&](const tbb::blocked_range<size_t>& range) {
    for (size_t k = range.begin(); k != range.end(); ++k) {
      const auto [i, j] = pairs[k];
      auto t0 = Clock::now();
      std::vector<FeatureMatch> putative;
      {
        auto a = cache.Get(i), b = cache.Get(j);
        putative = MatchDescriptors(*a, *b, options.match);
      }
      cache.Done(i);
      cache.Done(j);
      auto t1 = Clock::now();
      ns_match += std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count();
      VerifiedPair& vp = results[k];
      vp.image_id1 = i + 1;
      vp.image_id2 = j + 1;
      vp.num_putative = static_cast<uint32_t>(putative.size());
      if (putative.size() >= static_cast<size_t>(options.verify.min_inliers)) {
        geometry::Points2 x1(putative.size()), x2(putative.size());
        for (size_t m = 0; m < putative.size(); ++m) {
          const auto& k1 = features[i].keypoints[putative[m].idx1];
          const auto& k2 = features[j].keypoints[putative[m].idx2];
          x1[m] = {k1.x, k1.y};
          x2[m] = {k2.x, k2.y};
        }
        geometry::TwoViewOptions vopt = options.verify;
        vopt.seed = options.verify.seed ^ (uint64_t(i) << 32 | j);
        const auto r = geometry::VerifyTwoView(x1, x2, *cameras[i], *cameras[j], trusted[i] && trusted[j], vopt);
        vp.num_inliers_F = r.num_inliers_F;
        vp.num_inliers_E = r.num_inliers_E;
        vp.num_inliers_H = r.num_inliers_H;
        vp.geometry = ToPairGeometry(r.geometry);
        if (r.geometry != geometry::TwoViewClass::kRejected) {
          vp.F = r.F;
          vp.E = r.E;
          vp.H = r.H;
          vp.has_pose = r.has_pose;
          vp.R = r.R;
          vp.t = r.t;
          vp.median_triangulation_angle_deg = r.median_triangulation_angle_deg;
          vp.inliers.reserve(r.inliers.size());
          for (int m : r.inliers) vp.inliers.push_back(putative[m]);
          verified[k] = 1;
        }
      }
      ns_verify += std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t1).count();
      progress.Add();
    }
  });
  progress.Finish();
  cv::setNumThreads(cv_threads);
  stats.cpu_seconds_match = ns_match * 1e-9;
  stats.cpu_seconds_verify = ns_verify * 1e-9;

  // --- Outputs.
  std::vector<VerifiedPair> kept;
  nlohmann::json per_pair = nlohmann::json::array();
  size_t total_inliers = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const auto& vp = results[k];
    per_pair.push_back({{"image1", vp.image_id1},
                        {"image2", vp.image_id2},
                        {"putative", vp.num_putative},
                        {"inliers_F", vp.num_inliers_F},
                        {"inliers_E", vp.num_inliers_E},
                        {"inliers_H", vp.num_inliers_H},
                        {"inliers", vp.inliers.size()},
                        {"geometry", verified[k] ? GeometryName(vp.geometry) : "rejected"},
                        {"median_triangulation_angle_deg", vp.median_triangulation_angle_deg}});
    if (!verified[k]) continue;
    total_inliers += vp.inliers.size();
    stats.calibrated += vp.geometry == PairGeometry::kCalibrated;
    stats.uncalibrated += vp.geometry == PairGeometry::kUncalibrated;
    stats.planar_or_rotation += vp.geometry == PairGeometry::kPlanarOrRotation;
    kept.push_back(vp);
  }
  // --- The operator's tie points, keypoints and deleted matches.
  const fs::path tiepoints_path = options.tiepoints_file.value_or(ws.manual_dir() / "tiepoints.json");
  const fs::path manual_path = ManualMatchesPath(matches_dir);
  nlohmann::json manual_summary = {{"used", false}};
  core::EnsureDirectory(matches_dir);
  if (options.tiepoints_file || (options.use_tiepoints && fs::exists(tiepoints_path))) {
    io::FrameTable table = io::FrameTableOf(index);
    for (size_t i = 0; i < n; ++i) table[index.frames[i].name].num_keypoints = features[i].keypoints.size();
    const io::TiePoints tie_points = io::ReadTiePoints(tiepoints_path, &table);
    std::set<std::string> clicked;
    for (const auto& tp : tie_points.tie_points)
      for (const auto& o : tp.observations) clicked.insert(o.frame);
    for (const auto& kp : tie_points.keypoints) clicked.insert(kp.point.frame);
    std::map<uint32_t, cv::Mat> images;
    for (size_t i = 0; i < n; ++i)
      if (clicked.count(index.frames[i].name)) {
        images[i] = cv::imread((ws.frames_dir() / index.frames[i].name).string(), cv::IMREAD_COLOR);
        if (images[i].empty())
          spdlog::warn("match: cannot read frames/{}: its tie points get no descriptor", index.frames[i].name);
      }
    ManualMatches manual = AppendManualKeypoints(tie_points, index, images, &features, options.manual);
    const size_t pairs_before = kept.size();
    ApplyManualMatches(tie_points, index, features, options.manual, &manual, &kept);
    core::WriteJson(manual_path, manual.ToJson(index));
    nlohmann::json disagreeing = manual.ToJson(index)["disagreeing"];
    manual_summary = {{"used", true},
                      {"file", tiepoints_path.string()},
                      {"tie_points", tie_points.tie_points.size()},
                      {"keypoints", tie_points.keypoints.size()},
                      {"keypoint_matches_found", manual.keypoints_matched},
                      {"deleted_matches_removed", manual.deleted},
                      {"deleted_matches_not_found", manual.deleted_not_found},
                      {"pairs_added", kept.size() > pairs_before ? kept.size() - pairs_before : 0},
                      {"max_epipolar_px", options.manual.max_epipolar_px},
                      {"disagreeing", disagreeing}};
    for (const auto& d : manual.disagreeing)
      spdlog::warn("match: tie point \"{}\" is {:.1f} px from the epipolar line of {} / {} (kept)", d.id, d.epipolar_px,
                   index.frames[d.image1].name, index.frames[d.image2].name);
    spdlog::info("match: {} tie points, {} keypoints ({} matches found), {} deleted matches removed",
                 tie_points.tie_points.size(), tie_points.keypoints.size(), manual.keypoints_matched, manual.deleted);
  } else if (fs::exists(manual_path)) {
    fs::remove(manual_path);
  }
  stats.pairs_verified = kept.size();
  WriteMatches(kept, MatchesPath(matches_dir));
  stats.seconds_total = Since(t_start);
  const nlohmann::json summary = {
      {"images", n},
      {"pair_mode", PairModeName(mode)},
      {"pairs_tried", stats.pairs_tried},
      {"loop_closure_pairs", stats.loop_closure_pairs},
      {"pairs_verified", stats.pairs_verified},
      {"calibrated", stats.calibrated},
      {"uncalibrated", stats.uncalibrated},
      {"planar_or_rotation", stats.planar_or_rotation},
      {"total_inliers", total_inliers},
      {"mean_inliers_per_verified_pair", kept.empty() ? 0.0 : double(total_inliers) / kept.size()},
      {"timing",
       {{"seconds_total", stats.seconds_total},
        {"seconds_load", stats.seconds_load},
        {"seconds_pair_selection", stats.seconds_pairs},
        {"cpu_seconds_matching", stats.cpu_seconds_match},
        {"cpu_seconds_verification", stats.cpu_seconds_verify}}},
      {"options",
       {{"ratio", options.match.ratio},
        {"mutual", options.match.mutual},
        {"flann_checks", options.match.flann_checks},
        {"overlap", options.pairs.overlap},
        {"quadratic", options.pairs.quadratic},
        {"loop_closure_candidates", options.pairs.loop_closure_candidates},
        {"max_error_px", options.verify.max_error_px},
        {"min_inliers", options.verify.min_inliers}}},
      {"manual", manual_summary},
      {"pairs", per_pair}};
  core::WriteJson(MatchesSummaryPath(matches_dir), summary);
  spdlog::info(
      "match: {} / {} pairs verified ({} calibrated, {} uncalibrated, {} planar/rotation), {:.1f} s "
      "(matching {:.1f} s, verification {:.1f} s CPU)",
      stats.pairs_verified, stats.pairs_tried, stats.calibrated, stats.uncalibrated, stats.planar_or_rotation,
      stats.seconds_total, stats.cpu_seconds_match, stats.cpu_seconds_verify);
  return stats;
}

}  // namespace fmv3d::features
