#include "fmv3d/features/match_stage.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>

#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/threading.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/match_cache.h"
#include "fmv3d/features/operator_edits.h"
#include "fmv3d/features/spatial_pairs.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

// Bytes a keypoint costs while its image is matched: its descriptor as u8, float (FLANN) and int16 + int8 rows
// and blocks (brute force), the kd-forest's nodes.
constexpr double kBytesPerKeypoint = 1400;
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

// Each image's descriptors with their search structures (float rows, kd-forest or SIMD blocks: ~1.3 KB per
// keypoint), read from its feature file on first use. An image is released once every pair that needs it is done;
// and since quadratic and loop-closure pairs reach far beyond the sequential window, at most `capacity` images are
// held: the least recently used one that no thread is matching is evicted, and read again if a later pair needs it.
// Matching is deterministic whatever the evictions (the kd-forest is seeded per image).
class DescriptorCache {
 public:
  struct Entry {
    explicit Entry(Descriptors d, uint32_t id) : u8(std::move(d)), search(u8, id) {}
    Descriptors u8;
    ImageDescriptors search;  // points into u8
  };
  DescriptorCache(std::function<Descriptors(uint32_t)> load, size_t num_images, const std::vector<ImagePair>& pairs,
                  size_t capacity)
      : load_(std::move(load)),
        entries_(num_images),
        last_use_(num_images, 0),
        remaining_(num_images),
        capacity_(std::max<size_t>(capacity, 2)) {
    for (const auto& p : pairs) {
      ++remaining_[p.first];
      ++remaining_[p.second];
    }
  }
  std::shared_ptr<Entry> Get(uint32_t i) {
    std::lock_guard<std::mutex> lock(mutex_);
    last_use_[i] = ++tick_;
    if (entries_[i]) return entries_[i];
    while (held_ >= capacity_ && EvictOne()) {
    }
    entries_[i] = std::make_shared<Entry>(load_(i), i + 1);
    ++held_;
    ++loads_;
    peak_ = std::max(peak_, held_);
    return entries_[i];
  }
  void Done(uint32_t i) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (--remaining_[i] == 0 && entries_[i]) {
      entries_[i].reset();
      --held_;
    }
  }
  size_t loads() const { return loads_; }
  size_t peak() const { return peak_; }
  size_t capacity() const { return capacity_; }

 private:
  bool EvictOne() {  // the least recently used entry no thread holds; false when every held entry is in use
    int64_t victim = -1;
    for (size_t k = 0; k < entries_.size(); ++k)
      if (entries_[k] && entries_[k].use_count() == 1 && (victim < 0 || last_use_[k] < last_use_[victim]))
        victim = static_cast<int64_t>(k);
    if (victim < 0) return false;
    entries_[victim].reset();
    --held_;
    return true;
  }
  std::function<Descriptors(uint32_t)> load_;
  std::mutex mutex_;
  std::vector<std::shared_ptr<Entry>> entries_;
  std::vector<uint64_t> last_use_;
  std::vector<int> remaining_;
  size_t capacity_, held_ = 0, loads_ = 0, peak_ = 0;
  uint64_t tick_ = 0;
};

// The features of every frame, with each frame's camera prior; everything is checked against the index first.
struct LoadedFeatures {
  std::vector<FeatureSet> features;  // keypoints and colours; descriptors only where ApplyOperatorInput loads them
  std::vector<const core::Camera*> cameras;
  std::vector<bool> trusted;  // the camera is known (sensor database, EXIF, calibration), not a focal guess
};

LoadedFeatures LoadFeatures(const core::Workspace& ws, const io::FramesIndex& index) {
  const size_t n = index.frames.size();
  const fs::path frames_json = ws.frames_json();
  LoadedFeatures out;
  out.features.resize(n);
  std::vector<std::string> errors(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    try {
      const fs::path p = FeaturePath(ws.features_dir(), index.frames[i].name);
      if (!fs::exists(p)) throw Error(p.string() + " is missing; run `fmv3d features " + ws.name() + "` first");
      out.features[i] = ReadFeatures(p, /*descriptors=*/false);
      if (out.features[i].image_name != index.frames[i].name)
        throw Error(p.string() + ": holds features of '" + out.features[i].image_name + "', not '" +
                    index.frames[i].name + "' (re-run `fmv3d features --force`)");
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  });
  for (const auto& e : errors)
    if (!e.empty()) throw Error(e);
  out.cameras.resize(n);
  out.trusted.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const auto* prior = index.FindCamera(index.frames[i].camera_id);
    if (!prior)
      throw Error(frames_json.string() + ": frame '" + index.frames[i].name + "' refers to camera " +
                  std::to_string(index.frames[i].camera_id) + ", which is not in \"cameras\"");
    out.cameras[i] = &prior->camera;
    const auto& f = out.features[i];
    if (f.width != prior->camera.width || f.height != prior->camera.height)
      throw Error(frames_json.string() + ": frame '" + index.frames[i].name + "' is " + std::to_string(f.width) + "x" +
                  std::to_string(f.height) + " but camera " + std::to_string(prior->camera.id) + " is " +
                  std::to_string(prior->camera.width) + "x" + std::to_string(prior->camera.height) +
                  " (stale features? re-run `fmv3d features --force`)");
    const io::PriorKind kind = prior->prior_source.kind;
    out.trusted[i] = kind != io::PriorKind::kNone && kind != io::PriorKind::kGuess;
  }
  return out;
}

std::vector<std::string> FrameKeys(const core::Workspace& ws, const io::FramesIndex& index, const LoadedFeatures& in) {
  std::vector<std::string> keys(index.frames.size());
  tbb::parallel_for(size_t{0}, keys.size(), [&](size_t i) {
    const std::string camera = core::CameraToJson(*in.cameras[i]).dump() + (in.trusted[i] ? ":trusted" : ":guess");
    keys[i] = index.frames[i].name + ":" + FrameKey(FeaturePath(ws.features_dir(), index.frames[i].name), camera);
  });
  return keys;
}

std::vector<ImagePair> ChoosePairs(const io::FramesIndex& index, const DescriptorLoader& load,
                                   const PairOptions& options, PairMode* mode, MatchStageStats* stats) {
  const size_t n = index.frames.size();
  PairOptions pair_options = options;
  std::vector<Footprint> footprints;
  if (pair_options.mode == PairMode::kSpatial || pair_options.mode == PairMode::kAuto)
    footprints = FootprintsFromTelemetry(index);
  if (pair_options.mode == PairMode::kAuto && PreferSpatialPairs(index, footprints, pair_options)) {
    pair_options.mode = PairMode::kSpatial;
    spdlog::info("match: {} photos with GPS: pairs by overlapping ground footprints", n);
  }
  return SelectPairs(n, load, pair_options, mode, &stats->loop_closure_pairs, &footprints);
}

// Putative matches + two-view verification of one pair; `verified` is false when the pair is rejected.
VerifiedPair MatchPair(const LoadedFeatures& in, DescriptorCache* cache, uint32_t i, uint32_t j,
                       const MatchStageOptions& options, bool* verified, std::atomic<int64_t>* ns_match,
                       std::atomic<int64_t>* ns_verify) {
  const auto t0 = Clock::now();
  std::vector<FeatureMatch> putative;
  {
    auto a = cache->Get(i), b = cache->Get(j);
    putative = MatchDescriptors(a->search, b->search, options.match);
  }
  cache->Done(i);
  cache->Done(j);
  const auto t1 = Clock::now();
  *ns_match += std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count();
  VerifiedPair vp;
  vp.image_id1 = i + 1;
  vp.image_id2 = j + 1;
  vp.num_putative = static_cast<uint32_t>(putative.size());
  *verified = false;
  if (putative.size() >= static_cast<size_t>(options.verify.min_inliers)) {
    geometry::Points2 x1(putative.size()), x2(putative.size());
    for (size_t m = 0; m < putative.size(); ++m) {
      const auto& k1 = in.features[i].keypoints[putative[m].idx1];
      const auto& k2 = in.features[j].keypoints[putative[m].idx2];
      x1[m] = {k1.x, k1.y};
      x2[m] = {k2.x, k2.y};
    }
    geometry::TwoViewOptions vopt = options.verify;
    vopt.seed = options.verify.seed ^ (uint64_t(i) << 32 | j);
    const auto r =
        geometry::VerifyTwoView(x1, x2, *in.cameras[i], *in.cameras[j], in.trusted[i] && in.trusted[j], vopt);
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
      *verified = true;
    }
  }
  *ns_verify += std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t1).count();
  return vp;
}

// The keys a pair's automatic result is computed under (match_cache.h).
struct ResultKeys {
  std::string options;
  std::vector<std::string> frames;
};

// One pair's result on its way from matching to the files.
struct PairInFlight {
  VerifiedPair vp;
  bool verified = false;
};

// Takes the pairs' results in pair order as they come: writes them to automatic.* and keeps only their summary
// rows and which of them were verified.
class ResultSink {
 public:
  ResultSink(const fs::path& matches_dir, const ResultKeys& keys, MatchStageStats* stats)
      : automatic_(matches_dir, keys.options, keys.frames), stats_(stats) {}
  void Add(const ImagePair& pair, const VerifiedPair& vp, bool verified) {
    automatic_.Add(pair, vp, verified);
    per_pair_.push_back({{"image1", vp.image_id1},
                         {"image2", vp.image_id2},
                         {"putative", vp.num_putative},
                         {"inliers_F", vp.num_inliers_F},
                         {"inliers_E", vp.num_inliers_E},
                         {"inliers_H", vp.num_inliers_H},
                         {"inliers", vp.inliers.size()},
                         {"geometry", verified ? GeometryName(vp.geometry) : "rejected"},
                         {"median_triangulation_angle_deg", vp.median_triangulation_angle_deg}});
    if (verified) {
      verified_.push_back(added_);
      total_inliers_ += vp.inliers.size();
      stats_->calibrated += vp.geometry == PairGeometry::kCalibrated;
      stats_->uncalibrated += vp.geometry == PairGeometry::kUncalibrated;
      stats_->planar_or_rotation += vp.geometry == PairGeometry::kPlanarOrRotation;
    }
    ++added_;
  }
  void Finish() { automatic_.Finish(); }
  // The verified pairs' positions in automatic.bin, in pair order.
  std::vector<size_t> TakeVerified() { return std::move(verified_); }
  nlohmann::json TakePerPair() { return std::move(per_pair_); }
  size_t total_inliers() const { return total_inliers_; }

 private:
  AutomaticMatchesWriter automatic_;
  MatchStageStats* stats_;
  nlohmann::json per_pair_ = nlohmann::json::array();
  std::vector<size_t> verified_;
  size_t added_ = 0, total_inliers_ = 0;
};

// Descriptor images the memory budget holds at once.
size_t DescriptorCapacity(const LoadedFeatures& in, const MatchStageOptions& options) {
  size_t keypoints = 0;
  for (const auto& f : in.features) keypoints += f.keypoints.size();
  const double per_image =
      kBytesPerKeypoint * std::max(1.0, double(keypoints) / std::max<size_t>(1, in.features.size()));
  return std::max<size_t>(2 * core::NumThreads() + 2,
                          static_cast<size_t>(options.max_memory_mb * 1048576.0 / per_image));
}

// Every pair matched and verified in parallel, written in pair order by `sink` as soon as the pairs before it are:
// at most MatchPairsInFlight() results are held at once, whatever the pair count. Pairs whose automatic result
// `previous` holds for the same keys (match_cache.h) are read back instead of matched.
void MatchAndVerify(const LoadedFeatures& in, const DescriptorLoader& load, const std::vector<ImagePair>& pairs,
                    const MatchStageOptions& options, const AutomaticMatches& previous, const ResultKeys& keys,
                    ResultSink* sink, MatchStageStats* stats) {
  std::vector<const AutomaticMatches::Entry*> reuse(pairs.size());
  std::vector<ImagePair> todo_pairs;
  for (size_t k = 0; k < pairs.size(); ++k) {
    reuse[k] = previous.Find(pairs[k], keys.options, keys.frames);
    if (!reuse[k]) todo_pairs.push_back(pairs[k]);
  }
  stats->pairs_reused = pairs.size() - todo_pairs.size();
  if (stats->pairs_reused > 0)
    spdlog::info("match: {} of {} pairs unchanged since the last run: not matched again", stats->pairs_reused,
                 pairs.size());
  const int cv_threads = cv::getNumThreads();
  cv::setNumThreads(1);
  DescriptorCache cache([&load](uint32_t i) { return load(i); }, in.features.size(), todo_pairs,
                        DescriptorCapacity(in, options));
  std::atomic<int64_t> ns_match{0}, ns_verify{0};
  core::Progress progress("match", todo_pairs.size());
  // Pair k lives in slot k % tokens: the pairs in flight are consecutive (written in order), at most `tokens`.
  const size_t tokens = MatchPairsInFlight();
  std::vector<PairInFlight> slots(tokens);
  std::atomic<size_t> held{0};
  size_t next = 0, peak = 0;
  auto take_next = [&](tbb::flow_control& fc) -> size_t {
    if (next == pairs.size()) {
      fc.stop();
      return 0;
    }
    peak = std::max(peak, ++held);
    return next++;
  };
  auto match = [&](size_t k) {
    PairInFlight& p = slots[k % tokens];
    if (!reuse[k]) {
      const auto [i, j] = pairs[k];
      p.vp = MatchPair(in, &cache, i, j, options, &p.verified, &ns_match, &ns_verify);
      progress.Add();
    }
    return k;
  };
  auto write = [&](size_t k) {
    PairInFlight& p = slots[k % tokens];
    if (reuse[k]) {
      p.vp = previous.Read(*reuse[k]);
      p.verified = reuse[k]->verified;
    }
    sink->Add(pairs[k], p.vp, p.verified);
    p = PairInFlight{};
    --held;
  };
  tbb::parallel_pipeline(tokens, tbb::make_filter<void, size_t>(tbb::filter_mode::serial_in_order, take_next) &
                                     tbb::make_filter<size_t, size_t>(tbb::filter_mode::parallel, match) &
                                     tbb::make_filter<size_t, void>(tbb::filter_mode::serial_in_order, write));
  progress.Finish();
  cv::setNumThreads(cv_threads);
  sink->Finish();
  stats->cpu_seconds_match = ns_match * 1e-9;
  stats->cpu_seconds_verify = ns_verify * 1e-9;
  stats->descriptor_cache_capacity = cache.capacity();
  stats->descriptor_loads = cache.loads();
  stats->peak_cached_images = cache.peak();
  stats->peak_pairs_held = peak;
}

nlohmann::json SummaryJson(const MatchStageStats& stats, PairMode mode, const MatchStageOptions& options,
                           size_t total_inliers, nlohmann::json manual_summary, nlohmann::json per_pair) {
  return {{"images", stats.images},
          {"pair_mode", PairModeName(mode)},
          {"pairs_tried", stats.pairs_tried},
          {"pairs_reused", stats.pairs_reused},
          {"loop_closure_pairs", stats.loop_closure_pairs},
          {"pairs_verified", stats.pairs_verified},
          {"calibrated", stats.calibrated},
          {"uncalibrated", stats.uncalibrated},
          {"planar_or_rotation", stats.planar_or_rotation},
          {"total_inliers", total_inliers},
          {"mean_inliers_per_verified_pair",
           stats.pairs_verified == 0 ? 0.0 : double(total_inliers) / stats.pairs_verified},
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
          {"memory",
           {{"max_memory_mb", options.max_memory_mb},
            {"descriptor_cache_images", stats.descriptor_cache_capacity},
            {"peak_cached_images", stats.peak_cached_images},
            {"descriptor_loads", stats.descriptor_loads}}},
          {"manual", std::move(manual_summary)},
          {"pairs", std::move(per_pair)}};
}

}  // namespace

size_t MatchPairsInFlight() { return 4 * static_cast<size_t>(core::NumThreads()); }

MatchStageStats RunMatchStage(const core::Workspace& ws, const MatchStageOptions& options) {
  options.Check();
  const auto t_start = Clock::now();
  MatchStageStats stats;
  const auto index = io::ReadFramesIndex(ws.frames_json());
  stats.images = index.frames.size();
  LoadedFeatures in = LoadFeatures(ws, index);
  stats.seconds_load = Since(t_start);

  const auto t_pairs = Clock::now();
  PairMode mode = PairMode::kAuto;
  const DescriptorLoader load = [&](size_t i) {
    return ReadFeatures(FeaturePath(ws.features_dir(), index.frames[i].name)).descriptors;
  };
  const auto pairs = ChoosePairs(index, load, options.pairs, &mode, &stats);
  stats.pairs_tried = pairs.size();
  stats.seconds_pairs = Since(t_pairs);
  spdlog::info("match: {} images, {} pairs ({}{})", stats.images, pairs.size(), PairModeName(mode),
               mode == PairMode::kSequential
                   ? ", " + std::to_string(stats.loop_closure_pairs) + " loop-closure candidates"
                   : std::string());

  const ResultKeys keys{OptionsKey(options.match, options.verify), FrameKeys(ws, index, in)};
  ResultSink sink(ws.matches_dir(), keys, &stats);
  {
    const AutomaticMatches previous = options.reuse ? ReadAutomaticMatches(ws.matches_dir()) : AutomaticMatches{};
    MatchAndVerify(in, load, pairs, options, previous, keys, &sink, &stats);
  }
  const std::vector<size_t> verified = sink.TakeVerified();
  MatchFileReader automatic(AutomaticBinPath(ws.matches_dir()));
  OperatorEdits edits;
  nlohmann::json manual_summary =
      ApplyOperatorInput(ws, index, load, options, &in.features, &automatic, verified, &edits);
  stats.pairs_verified = WriteFinalMatches(&automatic, verified, edits, MatchesPath(ws.matches_dir()));
  if (edits.used && stats.pairs_verified > verified.size())
    manual_summary["pairs_added"] = stats.pairs_verified - verified.size();
  stats.seconds_total = Since(t_start);
  core::WriteJson(MatchesSummaryPath(ws.matches_dir()), SummaryJson(stats, mode, options, sink.total_inliers(),
                                                                    std::move(manual_summary), sink.TakePerPair()));
  spdlog::info(
      "match: {} / {} pairs verified ({} calibrated, {} uncalibrated, {} planar/rotation), {:.1f} s "
      "(matching {:.1f} s, verification {:.1f} s CPU)",
      stats.pairs_verified, stats.pairs_tried, stats.calibrated, stats.uncalibrated, stats.planar_or_rotation,
      stats.seconds_total, stats.cpu_seconds_match, stats.cpu_seconds_verify);
  return stats;
}

}  // namespace fmv3d::features
