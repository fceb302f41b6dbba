#include "fmv3d/mvs/dense_stage.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/mvs/fusion_window.h"

namespace fmv3d::mvs {

namespace fs = std::filesystem;

void DenseStageOptions::Check() const {
  if (max_size < 0) throw Error("dense: --max-size must be >= 0 (0 = full resolution)");
  if (max_size > 0 && max_size < 64) throw Error("dense: --max-size below 64 pixels leaves nothing to match");
  if (max_sources < 1 || max_sources > 16) throw Error("dense: --max-sources must be in [1, 16]");
  if (cache_views < 1) throw Error("dense: cache_views must be at least 1");
  if (!(max_memory_mb > 0)) throw Error("dense: --max-memory must be > 0 MB");
  if (references.coverage < 0) throw Error("dense: --reference-coverage must be >= 0 (0 = every view)");
  if (!(references.demand_fraction > 0 && references.demand_fraction <= 1))
    throw Error("dense: the reference cover's demand fraction must be in (0, 1]");
  if (!(references.cone_deg > 0 && references.cone_deg < 180))
    throw Error("dense: the reference cover's cone must be in (0, 180) degrees");
  selection.Check();
  patch_match.Check();
  fusion.Check();
}

std::string MapFileStem(const std::string& image_name) {
  std::string s = image_name;
  for (char& c : s)
    if (c == '/' || c == '\\') c = '_';
  return s;
}

namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Which views the stage works on: every registered view with a usable stereo neighbour is a source; the
// references (those that get a depth map) are a cover of the sparse points among them.
struct ViewPlan {
  std::map<uint32_t, ViewGeometry> geoms;
  std::map<uint32_t, ReferenceSelection> selection;            // every view's neighbours and depth range
  std::map<uint32_t, ReferenceSelection> reference_selection;  // among the references alone, when a subset
  std::vector<uint32_t> usable, references;
  nlohmann::json skipped = nlohmann::json::array();
  double seconds = 0;
  // Fusion checks each reference against its neighbours among the references.
  const std::map<uint32_t, ReferenceSelection>& fusion_selection() const {
    return references.size() < usable.size() ? reference_selection : selection;
  }
};

ViewPlan PlanViews(const fs::path& workspace, const core::Reconstruction& rec, const DenseStageOptions& options) {
  ViewPlan plan;
  for (const auto& [id, im] : rec.images) plan.geoms[id] = MakeViewGeometry(rec, id, options.max_size);
  const auto t_sel = Clock::now();
  plan.selection = SelectViews(rec, plan.geoms, options.selection);
  plan.seconds = SecondsSince(t_sel);
  for (const auto& [id, sel] : plan.selection) {
    if (sel.problem.empty()) {
      plan.usable.push_back(id);
    } else {
      spdlog::warn("dense: skipping view {}: {}", plan.geoms.at(id).name, sel.problem);
      plan.skipped.push_back({{"image", plan.geoms.at(id).name}, {"reason", sel.problem}});
    }
  }
  if (plan.usable.empty())
    throw Error(workspace.string() + ": no registered view has a usable stereo neighbour (" +
                (plan.selection.empty() ? std::string("empty model") : plan.selection.begin()->second.problem) + ")");
  plan.references = SelectReferenceViews(rec, plan.geoms, plan.usable, options.references);
  if (plan.references.size() < plan.usable.size()) {
    std::map<uint32_t, ViewGeometry> ref_geoms;
    for (uint32_t id : plan.references) ref_geoms[id] = plan.geoms.at(id);
    plan.reference_selection = SelectViews(rec, ref_geoms, options.selection);
    spdlog::info("dense: {} of {} views are references (each sparse point in {} of them)", plan.references.size(),
                 plan.usable.size(), options.references.coverage);
  }
  return plan;
}

// The depth-map passes and the fusion of one workspace's references.
class DenseRunner {
 public:
  DenseRunner(const core::Reconstruction& rec, const ViewPlan& plan, const fs::path& frames_dir,
              const fs::path& maps_dir, const DenseStageOptions& options)
      : plan_(plan),
        maps_dir_(maps_dir),
        options_(options),
        cache_(rec, plan.geoms, frames_dir,
               static_cast<size_t>(std::max(options.cache_views, options.max_sources + 2))) {
    for (const auto& [pid, p] : rec.points) {
      // The widest angle between the track's rays: how well the point's depth is known (fusion.h).
      std::vector<Eigen::Vector3d> rays;
      for (const auto& te : p.track)
        if (auto it = rec.images.find(te.image_id); it != rec.images.end())
          rays.push_back((p.xyz - it->second.pose.Centre()).normalized());
      double widest = 0;
      for (size_t a = 0; a < rays.size(); ++a)
        for (size_t b = a + 1; b < rays.size(); ++b)
          widest = std::max(widest, std::acos(std::clamp(rays[a].dot(rays[b]), -1.0, 1.0)));
      for (const auto& te : p.track) observed_[te.image_id].push_back({p.xyz, widest});
    }
  }

  fs::path MapPath(uint32_t id, const char* suffix) const {
    return maps_dir_ / (MapFileStem(plan_.geoms.at(id).name) + suffix);
  }
  double load_seconds() const { return cache_.load_seconds(); }

  // Photometric PatchMatch of every reference; returns the seconds spent in PatchMatch.
  double PhotometricPass() {
    double pm_seconds = 0;
    core::Progress progress("dense: photometric depth maps", plan_.references.size());
    for (uint32_t id : plan_.references) {
      PatchMatchInput in;
      const auto ref = cache_.Get(id);
      std::vector<std::shared_ptr<const View>> holds;
      for (uint32_t s : SourcesOf(id)) holds.push_back(cache_.Get(s));
      in.ref = ref.get();
      for (const auto& h : holds) in.sources.push_back(h.get());
      in.depth_min = plan_.selection.at(id).depth_min;
      in.depth_max = plan_.selection.at(id).depth_max;
      if (auto it = observed_.find(id); it != observed_.end())
        for (const auto& o : it->second) in.seeds.push_back(o.xyz);
      PatchMatchStats st;
      const DepthMap map = RunPatchMatch(in, options_.patch_match, &st);
      pm_seconds += st.seconds;
      WriteDepthMap(map, options_.geometric ? MapPath(id, ".photometric.dmap") : MapPath(id, ".dmap"));
      spdlog::debug("dense: {} photometric: {} valid pixels in {:.2f} s", plan_.geoms.at(id).name, st.valid_pixels,
                    st.seconds);
      progress.Add();
    }
    return pm_seconds;
  }

  // Geometric-consistency PatchMatch started from the photometric maps; returns the seconds in PatchMatch.
  double GeometricPass() {
    double pm_seconds = 0;
    core::Progress progress("dense: geometric depth maps", plan_.references.size());
    const std::set<uint32_t> reference_set(plan_.references.begin(), plan_.references.end());
    for (uint32_t id : plan_.references) {
      const DepthMap init = ReadDepthMap(MapPath(id, ".photometric.dmap"));
      PatchMatchInput in;
      const auto ref = cache_.Get(id);
      std::vector<std::shared_ptr<const View>> holds;
      std::vector<DepthMap> src_maps;
      const auto src_ids = SourcesOf(id);
      src_maps.reserve(src_ids.size());
      for (uint32_t s : src_ids) {
        holds.push_back(cache_.Get(s));
        src_maps.push_back(reference_set.count(s) ? ReadDepthMap(MapPath(s, ".photometric.dmap")) : DepthMap{});
      }
      in.ref = ref.get();
      for (size_t k = 0; k < holds.size(); ++k) {
        in.sources.push_back(holds[k].get());
        in.source_maps.push_back(src_maps[k].empty() ? nullptr : &src_maps[k]);
      }
      in.depth_min = plan_.selection.at(id).depth_min;
      in.depth_max = plan_.selection.at(id).depth_max;
      in.init = &init;
      PatchMatchStats st;
      const DepthMap map = RunPatchMatch(in, options_.patch_match, &st);
      pm_seconds += st.seconds;
      WriteDepthMap(map, MapPath(id, ".dmap"));
      progress.Add();
    }
    if (!options_.keep_photometric)
      for (uint32_t id : plan_.references) fs::remove(MapPath(id, ".photometric.dmap"));
    return pm_seconds;
  }

  struct Fused {
    size_t points = 0, valid_pixels = 0, total_pixels = 0;
    size_t window = 0, loads = 0, peak_resident = 0;  // the fusion window's capacity, map loads, most views held
    FusionStats stats;
  };
  // Fuses the depth maps straight into `ply` (previews written while the maps are first read). Neither the cloud
  // nor every map is held: the maps stream through a window sized to the memory budget (fusion_window.h).
  Fused Fuse(const fs::path& ply) {
    Fused out;
    std::map<uint32_t, std::set<uint32_t>> links;
    for (uint32_t id : plan_.references)
      for (const auto& nb : plan_.fusion_selection().at(id).neighbours) {
        links[id].insert(nb.image_id);
        links[nb.image_id].insert(id);  // symmetric: a view checks every view that chose it too
      }
    std::vector<uint32_t> ids = plan_.references;
    std::sort(ids.begin(), ids.end());
    core::Progress progress("dense: loading maps for fusion", ids.size());
    std::set<uint32_t> seen;
    auto load = [&](uint32_t id) {
      const DepthMap map = ReadDepthMap(MapPath(id, ".dmap"));
      if (seen.insert(id).second) {  // once per view, however often the window reloads it
        if (options_.previews && !options_.fuse_only)
          WriteDepthPreview(map, MapPath(id, ".depth.png"), MapPath(id, ".normal.png"));
        out.valid_pixels += static_cast<size_t>(map.CountValid());
        out.total_pixels += map.depth.total();
        progress.Add();
      }
      const auto view = cache_.Get(id);
      FusionView fv = MakeFusionView(plan_.geoms.at(id), map, view->color,
                                     std::vector<uint32_t>(links[id].begin(), links[id].end()));
      if (auto it = observed_.find(id); it != observed_.end()) fv.sparse = it->second;
      if (options_.fusion.max_relative_uncertainty > 0)
        fv.texture = TexturePrecisionMap(view->color, options_.patch_match.window_radius);
      return fv;
    };
    FusionWindow window(ids, load, FusionWindowFor(ids, links), options_.fusion);
    out.points = FuseDepthMapsToPly(window, options_.fusion, ply, &out.stats);
    progress.Finish();
    out.window = window.capacity();
    out.loads = window.loads();
    out.peak_resident = window.peak_resident();
    return out;
  }

 private:
  // The fusion window's capacity under the memory budget, less what the undistorted-view cache holds; never
  // below a reference with all its neighbours.
  size_t FusionWindowFor(const std::vector<uint32_t>& ids, const std::map<uint32_t, std::set<uint32_t>>& links) const {
    size_t min_views = 1;
    for (uint32_t id : ids) {
      size_t n = 1;
      if (auto it = links.find(id); it != links.end())
        for (uint32_t j : it->second) n += std::binary_search(ids.begin(), ids.end(), j) && j != id;
      min_views = std::max(min_views, n);
    }
    const auto& g = plan_.geoms.at(ids.front());
    const double pixels = static_cast<double>(g.width) * g.height;
    const double cache_mb = static_cast<double>(cache_.capacity()) * pixels * kViewBytesPerPixel / 1048576.0;
    const double budget_mb = std::max(options_.max_memory_mb - cache_mb, 1.0);
    return ChooseFusionWindow(ids.size(), min_views, pixels * kFusionBytesPerPixel, budget_mb);
  }

  std::vector<uint32_t> SourcesOf(uint32_t id) const {
    std::vector<uint32_t> s;
    for (const auto& nb : plan_.selection.at(id).neighbours) {
      if (static_cast<int>(s.size()) >= options_.max_sources) break;
      s.push_back(nb.image_id);
    }
    return s;
  }

  const ViewPlan& plan_;
  const fs::path maps_dir_;
  const DenseStageOptions& options_;
  ViewCache cache_;
  // The sparse points each view observed, with their parallax: PatchMatch's seeds and fusion's sparse check.
  std::map<uint32_t, std::vector<SparseObservation>> observed_;
};

struct DenseTimings {
  double photometric = 0, photometric_pm = 0, geometric = 0, geometric_pm = 0, fusion = 0;
};

nlohmann::json DenseReport(const core::Reconstruction& rec, const ViewPlan& plan, const DenseRunner::Fused& fused,
                           const DenseTimings& t, double load_seconds, double total_seconds, const fs::path& ply,
                           const DenseStageOptions& options) {
  const FusionStats& fstats = fused.stats;
  nlohmann::json hist = nlohmann::json::object();
  double mean_views = 0;
  for (const auto& [k, n] : fstats.views_histogram) {
    hist[std::to_string(k)] = n;
    mean_views += static_cast<double>(k) * n;
  }
  if (fused.points > 0) mean_views /= static_cast<double>(fused.points);
  const auto& g0 = plan.geoms.at(plan.references.front());
  const double n_refs = static_cast<double>(plan.references.size());
  return {
      {"registered_images", rec.images.size()},
      {"views_used", plan.usable.size()},
      {"reference_views", plan.references.size()},
      {"reference_coverage", options.references.coverage},
      {"views_skipped", plan.skipped},
      {"working_resolution", {g0.width, g0.height}},
      {"max_size", options.max_size},
      {"max_sources", options.max_sources},
      {"geometric_pass", options.geometric},
      {"points", fused.points},
      {"valid_depth_fraction", fused.total_pixels ? static_cast<double>(fused.valid_pixels) / fused.total_pixels : 0.0},
      {"fusion",
       {{"candidates", fstats.candidates},
        {"rejected_too_few_views", fstats.rejected_support},
        {"rejected_visibility", fstats.rejected_visibility},
        {"edge_pixels_removed", fstats.edge_pixels},
        {"edge_erosion_px", options.fusion.edge_erosion_px},
        {"sparse_contradicted_pieces", fstats.sparse_pieces},
        {"sparse_contradicted_pixels", fstats.sparse_pixels},
        {"sparse_tolerance", options.fusion.sparse_tolerance},
        {"rejected_uncertainty", fstats.rejected_uncertainty},
        {"max_relative_uncertainty", options.fusion.max_relative_uncertainty},
        {"median_normal_sigma_per_footprint", fstats.median_uncertainty},
        {"max_normal_sigma_per_footprint", fstats.max_uncertainty},
        {"sigma_scale", fstats.sigma_scale},
        {"texture_floor", fstats.texture_floor},
        {"sigma_coverage",
         options.fusion.write_sigma ? nlohmann::json(options.fusion.sigma_coverage) : nlohmann::json()},
        {"mean_consistent_views", mean_views},
        {"consistent_views_histogram", hist}}},
      {"seconds",
       {{"view_selection", plan.seconds},
        {"load_undistort", load_seconds},
        {"photometric", t.photometric},
        {"photometric_per_view", t.photometric_pm / n_refs},
        {"geometric", t.geometric},
        {"geometric_per_view", options.geometric ? t.geometric_pm / n_refs : 0.0},
        {"fusion", t.fusion},
        {"total", total_seconds}}},
      {"memory",
       {{"max_memory_mb", options.max_memory_mb},
        {"fusion_window_views", fused.window},
        {"fusion_map_loads", fused.loads},
        {"fusion_peak_views", fused.peak_resident}}},
      {"output", ply.string()}};
}

}  // namespace

nlohmann::json RunDenseStage(const core::Workspace& workspace, const DenseStageOptions& options) {
  options.Check();
  const auto t_start = Clock::now();
  const fs::path sparse_dir = workspace.sparse_dir(), frames_dir = workspace.frames_dir();
  const fs::path dense_dir = workspace.dense_dir(), maps_dir = dense_dir / "maps", report_dir = workspace.report_dir();
  workspace.Require(sparse_dir / "images.txt", "sparse");
  const core::Reconstruction rec = io::ReadColmapText(sparse_dir);
  if (rec.images.size() < 2)
    throw Error(workspace.name() + ": the sparse model has " + std::to_string(rec.images.size()) +
                " registered image(s); dense stereo needs at least 2");

  const ViewPlan plan = PlanViews(workspace.root(), rec, options);
  core::EnsureDirectory(maps_dir);
  core::EnsureDirectory(report_dir);
  DenseRunner runner(rec, plan, frames_dir, maps_dir, options);
  if (options.fuse_only)
    for (uint32_t id : plan.references)
      if (!fs::exists(runner.MapPath(id, ".dmap")))
        throw Error(runner.MapPath(id, ".dmap").string() +
                    ": no depth map to fuse — run `fmv3d dense` without --fuse-only");

  DenseTimings t;
  const auto t_photo = Clock::now();
  if (!options.fuse_only) t.photometric_pm = runner.PhotometricPass();
  t.photometric = SecondsSince(t_photo);
  const auto t_geom = Clock::now();
  if (options.geometric && !options.fuse_only) t.geometric_pm = runner.GeometricPass();
  t.geometric = SecondsSince(t_geom);
  const auto t_fuse = Clock::now();
  const fs::path ply = dense_dir / "fused.ply";
  const DenseRunner::Fused fused = runner.Fuse(ply);
  if (fused.points == 0)
    spdlog::warn("dense: fusion produced no points (no pixel was consistent in {} views)", options.fusion.min_views);
  t.fusion = SecondsSince(t_fuse);

  nlohmann::json report = DenseReport(rec, plan, fused, t, runner.load_seconds(), SecondsSince(t_start), ply, options);
  core::WriteJson(report_dir / "dense.json", report);
  spdlog::info("dense: {} points from {} views ({} skipped) in {:.1f} s", fused.points, plan.references.size(),
               plan.skipped.size(), SecondsSince(t_start));
  return report;
}

}  // namespace fmv3d::mvs
