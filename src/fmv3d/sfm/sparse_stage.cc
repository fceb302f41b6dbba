#include "fmv3d/sfm/sparse_stage.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <set>

#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/manual_matches.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/sfm/mapper_report.h"
#include "fmv3d/sfm/relocalise.h"
#include "fmv3d/sfm/sparse_memory.h"

namespace fmv3d::sfm {

namespace fs = std::filesystem;

void WritePointsPly(const core::Reconstruction& rec, const fs::path& path) {
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw Error(tmp.string() + ": cannot write");
    out << "ply\nformat binary_little_endian 1.0\nelement vertex " << rec.points.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
           "property uchar blue\nend_header\n";
    for (const auto& [id, p] : rec.points) {
      const float xyz[3] = {static_cast<float>(p.xyz.x()), static_cast<float>(p.xyz.y()),
                            static_cast<float>(p.xyz.z())};
      out.write(reinterpret_cast<const char*>(xyz), sizeof xyz);
      out.write(reinterpret_cast<const char*>(p.rgb.data()), 3);
    }
    if (!out) throw Error(tmp.string() + ": write failed");
  });
}

// Images now registered in the largest model leave the other models, whose shrunken remains are dropped below
// the mapper's minimum model size.
void LeaveOtherModels(const std::vector<uint32_t>& registered, int min_model_size, MapperResult* result) {
  core::Reconstruction& model = result->models[0];
  std::set<uint32_t> moved(registered.begin(), registered.end());
  std::vector<core::Reconstruction> kept = {std::move(model)};
  for (size_t m = 1; m < result->models.size(); ++m) {
    core::Reconstruction& rec = result->models[m];
    for (uint32_t id : moved) {
      if (!rec.images.count(id)) continue;
      for (int64_t pid : rec.images.at(id).point3d_ids) {
        if (pid == core::kNoPoint3D) continue;
        auto& track = rec.points.at(static_cast<uint64_t>(pid)).track;
        track.erase(
            std::remove_if(track.begin(), track.end(), [id](const core::TrackElement& e) { return e.image_id == id; }),
            track.end());
      }
      rec.images.erase(id);
    }
    for (auto it = rec.points.begin(); it != rec.points.end();) {
      if (it->second.track.size() < 2) {
        for (const auto& el : it->second.track)
          rec.images.at(el.image_id).point3d_ids[el.point2d_idx] = core::kNoPoint3D;
        it = rec.points.erase(it);
      } else {
        ++it;
      }
    }
    if (static_cast<int>(rec.images.size()) >= min_model_size) kept.push_back(std::move(rec));
  }
  result->models = std::move(kept);
}

// Images outside the largest model retried against it (relocalise.h); those that register leave the other
// models, whose shrunken remains are dropped below the mapper's minimum model size.
// The feature sets (descriptors included) are read only when there are candidates: the mapper's peak holds none.
nlohmann::json RelocaliseLeftOut(const MapperInput& input,
                                 const std::function<const std::vector<features::FeatureSet>&()>& feature_sets,
                                 const SparseStageOptions& stage, MapperResult* result) {
  const auto& options = stage.relocalise;
  if (!options.enabled || result->models.empty()) return {{"enabled", options.enabled}};
  core::Reconstruction& model = result->models[0];
  std::map<uint32_t, const features::FeatureSet*> feats;
  std::vector<RelocaliseCandidate> candidates;
  std::map<uint32_t, core::Camera> cameras;
  for (const auto& [id, c] : input.cameras) cameras[id] = c.camera;
  for (const auto& im : input.images)
    if (!model.images.count(im.id) && !im.keypoints.empty()) candidates.push_back({im.id, im.camera_id, im.name});
  if (candidates.empty()) return {{"enabled", true}, {"candidates", 0}};
  const std::vector<features::FeatureSet>& sets = feature_sets();
  for (size_t i = 0; i < input.images.size(); ++i) feats[input.images[i].id] = &sets[i];
  const RelocaliseStats st = RelocaliseImages(&model, candidates, feats, cameras, options.options);
  for (uint32_t id : st.registered) result->left_out.erase(id);
  for (const auto& [id, why] : st.still_failed)
    if (result->left_out.count(id)) result->left_out[id] += "; relocalisation: " + why;
  LeaveOtherModels(st.registered, stage.mapper.min_model_size, result);
  spdlog::info("relocalise: {} of {} left-out images registered ({} observations, {} new points, {:.1f} s)",
               st.registered.size(), candidates.size(), st.observations_added, st.points_added, st.seconds);
  return {{"enabled", true},
          {"candidates", candidates.size()},
          {"registered", st.registered.size()},
          {"observations_added", st.observations_added},
          {"points_added", st.points_added},
          {"rounds", st.rounds},
          {"seconds", st.seconds}};
}

void SparseStageOptions::Check() const {
  mapper.Check();
  relocalise.options.Check();
  manual.options.Check();
  if (focal_px < 0) throw Error("sparse: --focal must be > 0 pixels");
  if (hfov_deg < 0 || hfov_deg >= 180) throw Error("sparse: --hfov must be in (0, 180) degrees");
  if (focal_px > 0 && hfov_deg > 0) throw Error("sparse: give --focal or --hfov, not both");
  if (!(max_memory_mb > 0)) throw Error("sparse: --max-memory must be > 0 MB");
}

namespace {

// What the sparse stage reads from the workspace: the mapper's input, the operator's tie-point tracks, and where
// the feature sets are. The feature sets themselves (128 B of descriptor per keypoint, most of the input) are kept
// only when the mapper's guided completion reads the descriptors; otherwise each is dropped once its keypoints are
// copied, and relocalisation reads them again (ReadFeatureSets).
struct SparseStageInput {
  MapperInput mapper;
  std::vector<features::FeatureSet> feature_sets;  // per frame, in frames.json order; empty unless kept
  std::vector<fs::path> feature_paths;             // per frame; empty when the frame has no feature file
  features::ManualMatches manual_matches;          // the tie points' appended keypoints (when manual)
  std::string manual_source;
  std::vector<TieTrack> tie_tracks;
  bool manual = false;  // the operator's tie points are in use
};

// Every frame's feature set as the mapper saw it: the file's, with the operator's keypoints appended.
std::vector<features::FeatureSet> ReadFeatureSets(const SparseStageInput& in) {
  std::vector<features::FeatureSet> sets(in.feature_paths.size());
  for (size_t i = 0; i < sets.size(); ++i)
    if (!in.feature_paths[i].empty()) sets[i] = features::ReadFeatures(in.feature_paths[i]);
  if (in.manual)
    for (const auto& [i, ap] : in.manual_matches.appended)
      features::AppendToFeatureSet(ap, &sets[i], in.manual_source + ": frame " + in.mapper.images[i].name);
  return sets;
}

// The cameras of frames.json, with the options' focal prior (which counts as known) when one is given.
std::map<uint32_t, MapperCamera> SparseCameras(const io::FramesIndex& index, const SparseStageOptions& options) {
  std::map<uint32_t, MapperCamera> cameras;
  for (const auto& c : index.cameras) {
    MapperCamera mc;
    mc.camera = c.camera;
    mc.focal_known = c.prior_source.kind != io::PriorKind::kGuess;
    // A focal stated by the camera (EXIF) or the sensor database is a nominal lens focal: real lenses are within
    // about 1% of it. Its prior keeps f where the images leave it free (a nadir survey from one height).
    if (c.prior_source.kind == io::PriorKind::kExif || c.prior_source.kind == io::PriorKind::kSensorDb)
      mc.focal_prior_sigma = 0.01;
    if (options.focal_px > 0 || options.hfov_deg > 0) {
      const double f = options.focal_px > 0 ? options.focal_px
                                            : 0.5 * mc.camera.width / std::tan(0.5 * options.hfov_deg * M_PI / 180);
      mc.camera.f = f;
      mc.focal_known = true;
      mc.focal_prior_sigma = 0;
      spdlog::info("camera {}: focal prior {:.1f} px from {}", c.camera.id, f,
                   options.focal_px > 0 ? "--focal" : "--hfov");
    }
    if (mc.focal_prior_sigma > 0)
      spdlog::info("camera {}: focal {:.1f} px from {}, a prior of σ {:.0f}% in bundle adjustment", c.camera.id,
                   mc.camera.f, io::PriorSourceName(c.prior_source), 100 * mc.focal_prior_sigma);
    cameras[c.camera.id] = mc;
  }
  return cameras;
}

// The operator's tie points: the keypoints `match` appended (features/manual_matches.h), appended again to the
// images here, and their tracks.
void AddTiePoints(const features::ManualMatches& mm, double weight, const std::string& source, SparseStageInput* in,
                  std::vector<size_t>* num_kp) {
  for (const auto& [i, ap] : mm.appended) {
    MapperImage& im = in->mapper.images[i];
    if (ap.first_index != im.keypoints.size())
      throw Error(source + ": frame " + im.name + ": " + std::to_string(im.keypoints.size()) +
                  " automatic keypoints, not " + std::to_string(ap.first_index) +
                  " (stale matches/manual.json: run `fmv3d match` again)");
    if (!in->feature_sets.empty())
      features::AppendToFeatureSet(ap, &in->feature_sets[i], source + ": frame " + im.name);
    if (im.colors.size() == im.keypoints.size()) im.colors.insert(im.colors.end(), ap.colors.begin(), ap.colors.end());
    for (const auto& k : ap.keypoints) im.keypoints.emplace_back(k.x, k.y);
    (*num_kp)[i] = im.keypoints.size();
    in->mapper.manual_from[im.id] = ap.first_index;
  }
  in->mapper.manual_weight = weight;
  for (const auto& t : mm.tracks) {
    if (t.kind != features::ManualTrackKind::kTiePoint) continue;
    TieTrack tt{t.id, {}};
    for (const auto& o : t.observations) tt.observations.push_back({o.image + 1, o.keypoint});
    in->tie_tracks.push_back(std::move(tt));
  }
}

SparseStageInput ReadSparseStageInput(const core::Workspace& ws, const SparseStageOptions& options) {
  auto require = [&](const fs::path& p, const char* cmd) {
    if (!fs::exists(p))
      throw Error(ws.name() + ": no " + fs::relative(p, ws.root()).string() + " — run `fmv3d " + cmd + "` first");
  };
  require(ws.frames_json(), "frames");
  require(ws.features_dir(), "features");
  require(features::MatchesPath(ws.matches_dir()), "match");
  const io::FramesIndex index = io::ReadFramesIndex(ws.frames_json());
  SparseStageInput in;
  in.mapper.cameras = SparseCameras(index, options);
  std::vector<size_t> num_kp;
  const bool keep_sets = options.mapper.guided_completion;
  if (keep_sets) in.feature_sets.resize(index.frames.size());
  in.feature_paths.resize(index.frames.size());
  for (size_t i = 0; i < index.frames.size(); ++i) {
    const auto& fr = index.frames[i];
    MapperImage im;
    im.id = static_cast<uint32_t>(i + 1);
    im.camera_id = fr.camera_id;
    im.name = fr.name;
    const fs::path fp = features::FeaturePath(ws.features_dir(), fr.name);
    if (fs::exists(fp)) {
      in.feature_paths[i] = fp;
      features::FeatureSet fs_ = features::ReadFeatures(fp);
      im.keypoints.reserve(fs_.keypoints.size());
      im.scales.reserve(fs_.keypoints.size());
      for (const auto& k : fs_.keypoints) im.keypoints.emplace_back(k.x, k.y), im.scales.push_back(k.scale);
      if (fs_.colors.size() == fs_.keypoints.size()) im.colors = fs_.colors;
      if (keep_sets) in.feature_sets[i] = std::move(fs_);
    }
    num_kp.push_back(im.keypoints.size());
    in.mapper.images.push_back(std::move(im));
  }
  const fs::path manual_path = features::ManualMatchesPath(ws.matches_dir());
  in.manual = options.manual.enabled && fs::exists(manual_path);
  if (in.manual) {
    in.manual_matches = features::ManualMatches::FromJson(core::ReadJson(manual_path), index);
    in.manual_source = manual_path.string();
    AddTiePoints(in.manual_matches, options.manual.options.weight, in.manual_source, &in, &num_kp);
  }
  const fs::path matches_path = features::MatchesPath(ws.matches_dir());
  in.mapper.pairs = features::ReadMatches(matches_path);
  features::ValidateMatches(in.mapper.pairs, num_kp, matches_path.string());
  // The descriptors stay in feature_sets (a moved vector keeps its elements where they are).
  for (size_t i = 0; i < in.feature_sets.size(); ++i) {
    const features::Descriptors& d = in.feature_sets[i].descriptors;
    if (static_cast<size_t>(d.rows()) == in.mapper.images[i].keypoints.size() && d.rows() > 0)
      in.mapper.images[i].descriptors = &d;
  }
  return in;
}

// Left-out frames registered into the largest model with the operator's tie points (manual_registration.h);
// returns the report's "manual" section.
nlohmann::json RegisterTiePointFrames(const SparseStageInput& in, const SparseStageOptions& options,
                                      MapperResult* result) {
  const MapperInput& input = in.mapper;
  std::map<uint32_t, std::vector<Eigen::Vector2d>> keypoints;
  std::map<uint32_t, std::string> names;
  std::map<uint32_t, uint32_t> image_cameras;
  std::map<uint32_t, core::Camera> cameras;
  for (const auto& im : input.images) {
    keypoints[im.id] = im.keypoints;
    names[im.id] = im.name;
    image_cameras[im.id] = im.camera_id;
  }
  for (const auto& [id, c] : input.cameras) cameras[id] = c.camera;
  const ManualRegistrationResult mr =
      RegisterWithTiePoints(&result->models[0], in.tie_tracks, keypoints, names, image_cameras, cameras,
                            input.manual_from, options.manual.options);
  for (uint32_t id : mr.registered) result->left_out.erase(id);
  for (const auto& [id, why] : mr.still_failed)
    if (result->left_out.count(id)) result->left_out[id] += "; tie points: " + why;
  LeaveOtherModels(mr.registered, options.mapper.min_model_size, result);
  nlohmann::json report = mr.ToJson(names);
  report["used"] = true;
  report["weight"] = options.manual.options.weight;
  report["min_tie_points"] = options.manual.options.min_tie_points;
  return report;
}

// Every model as a COLMAP text model with its sparse.ply: the largest in WS/sparse, the others in numbered
// sub-folders. Stale sub-models of an earlier run must not survive next to the new ones.
void WriteSparseModels(const core::Workspace& ws, const std::vector<core::Reconstruction>& models) {
  core::EnsureDirectory(ws.sparse_dir());
  core::EnsureDirectory(ws.report_dir());
  for (int k = 1; fs::exists(ws.sparse_dir() / std::to_string(k)); ++k)
    fs::remove_all(ws.sparse_dir() / std::to_string(k));
  for (size_t m = 0; m < models.size(); ++m) {
    const fs::path dir = m == 0 ? ws.sparse_dir() : ws.sparse_dir() / std::to_string(m);
    core::EnsureDirectory(dir);
    io::WriteColmapText(models[m], dir);
    WritePointsPly(models[m], dir / "sparse.ply");
  }
}

// The bound known before mapping (after thinning, if the budget needed it) and the estimate from the observations
// the models hold (sparse_memory.h).
nlohmann::json MemoryReport(const SparseThinning& t, const std::vector<core::Reconstruction>& models,
                            double budget_mb) {
  size_t observations = 0;
  for (const auto& model : models)
    for (const auto& [id, point] : model.points) observations += point.track.size();
  nlohmann::json j = {
      {"max_memory_mb", budget_mb},
      {"bound_mb", t.bound_after_mb},
      {"estimated_mb", EstimateSparseMemoryMb(observations, t.after.keypoints, t.after.correspondences)},
      {"within_budget", t.fits},
      {"keypoints", t.after.keypoints},
      {"matched_keypoints", t.after.matched_keypoints},
      {"correspondences", t.after.correspondences},
      {"observations", observations}};
  if (t.thinned)
    j["thinning"] = {{"keep_fraction", t.keep_fraction},
                     {"bound_before_mb", t.bound_before_mb},
                     {"matched_keypoints_before", t.before.matched_keypoints},
                     {"correspondences_before", t.before.correspondences}};
  return j;
}

}  // namespace

nlohmann::json RunSparseStage(const core::Workspace& ws, const SparseStageOptions& options) {
  options.Check();
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  SparseStageInput in = ReadSparseStageInput(ws, options);
  MapperInput& input = in.mapper;
  const double load_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  const SparseThinning thinning =
      ThinToMemoryBudget(input.images, input.manual_from, options.max_memory_mb, &input.pairs);
  if (thinning.thinned)
    spdlog::warn(
        "sparse: the model could need {:.0f} MB, above --max-memory {:g} MB: mapping with {:.0f}% of each image's "
        "matched "
        "keypoints, the most connected spread over the image ({} of {} correspondences; bound now {:.0f} MB)",
        thinning.bound_before_mb, options.max_memory_mb, 100 * thinning.keep_fraction, thinning.after.correspondences,
        thinning.before.correspondences, thinning.bound_after_mb);
  else if (!thinning.fits)
    spdlog::warn(
        "sparse: the model may need up to {:.0f} MB ({} matched keypoints, {} correspondences), above --max-memory "
        "{:g} MB even with a fifth of its matches; bundle adjustment holds every observation at once: fewer features "
        "per image or fewer keyframes lower it",
        thinning.bound_before_mb, thinning.before.matched_keypoints, thinning.before.correspondences,
        options.max_memory_mb);

  MapperResult result = RunIncrementalMapper(input, options.mapper);
  std::vector<features::FeatureSet> reread;
  auto feature_sets = [&]() -> const std::vector<features::FeatureSet>& {
    if (!in.feature_sets.empty()) return in.feature_sets;
    if (reread.empty()) reread = ReadFeatureSets(in);
    return reread;
  };
  const nlohmann::json relocalisation = RelocaliseLeftOut(input, feature_sets, options, &result);
  reread = {};
  nlohmann::json manual_report = {{"used", in.manual}};
  if (in.manual && !result.models.empty()) manual_report = RegisterTiePointFrames(in, options, &result);

  const auto write_start = Clock::now();
  WriteSparseModels(ws, result.models);
  nlohmann::json report = SparseReport(input, result);
  report["relocalisation"] = relocalisation;
  report["manual"] = manual_report;
  report["memory"] = MemoryReport(thinning, result.models, options.max_memory_mb);
  report["seconds"] = {{"load", load_seconds},
                       {"mapping", result.stats.seconds.total},
                       {"write", std::chrono::duration<double>(Clock::now() - write_start).count()},
                       {"total", std::chrono::duration<double>(Clock::now() - start).count()}};
  core::WriteJson(ws.report_dir() / "sparse.json", report);
  const core::Reconstruction* best = result.models.empty() ? nullptr : &result.models[0];
  if (!best) throw Error(ws.name() + ": no model could be reconstructed (see report/sparse.json for the reasons)");
  spdlog::info("sparse: {} / {} images registered, {} points, mean track {:.2f}, reprojection {:.3f} px",
               best->images.size(), input.images.size(), best->points.size(), best->MeanTrackLength(),
               best->MeanReprojectionError());
  return report;
}

}  // namespace fmv3d::sfm
