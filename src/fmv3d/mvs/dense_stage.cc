#include "fmv3d/mvs/dense_stage.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/io/colmap_model.h"

namespace fmv3d::mvs {

namespace fs = std::filesystem;

void DenseStageOptions::Check() const {
  if (max_size < 0) throw Error("dense: --max-size must be >= 0 (0 = full resolution)");
  if (max_size > 0 && max_size < 64) throw Error("dense: --max-size below 64 pixels leaves nothing to match");
  if (max_sources < 1 || max_sources > 16) throw Error("dense: --max-sources must be in [1, 16]");
  if (cache_views < 1) throw Error("dense: cache_views must be at least 1");
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

nlohmann::json RunDenseStage(const fs::path& workspace, const DenseStageOptions& options) {
  options.Check();
  using Clock = std::chrono::steady_clock;
  const auto t_start = Clock::now();
  auto seconds_since = [](Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); };
  const fs::path sparse_dir = workspace / "sparse", frames_dir = workspace / "frames";
  const fs::path dense_dir = workspace / "dense", maps_dir = dense_dir / "maps", report_dir = workspace / "report";
  if (!fs::exists(sparse_dir / "images.txt"))
    throw Error(workspace.string() + ": no sparse/images.txt — run `fmv3d sparse` first");
  const core::Reconstruction rec = io::ReadColmapText(sparse_dir);
  if (rec.images.size() < 2)
    throw Error(workspace.string() + ": the sparse model has " + std::to_string(rec.images.size()) +
                " registered image(s); dense stereo needs at least 2");

  // --- Views and view selection.
  std::map<uint32_t, ViewGeometry> geoms;
  for (const auto& [id, im] : rec.images) geoms[id] = MakeViewGeometry(rec, id, options.max_size);
  const auto t_sel = Clock::now();
  const auto selection = SelectViews(rec, geoms, options.selection);
  const double sel_seconds = seconds_since(t_sel);
  std::vector<uint32_t> usable;
  nlohmann::json skipped = nlohmann::json::array();
  for (const auto& [id, sel] : selection) {
    if (sel.problem.empty()) {
      usable.push_back(id);
    } else {
      spdlog::warn("dense: skipping view {}: {}", geoms.at(id).name, sel.problem);
      skipped.push_back({{"image", geoms.at(id).name}, {"reason", sel.problem}});
    }
  }
  if (usable.empty())
    throw Error(workspace.string() + ": no registered view has a usable stereo neighbour (" +
                (selection.empty() ? std::string("empty model") : selection.begin()->second.problem) + ")");
  // Reference views (depth maps); every usable view stays a stereo source. Fusion checks each reference
  // against its neighbours among the references: selected again on those views alone.
  const std::vector<uint32_t> all_usable = usable;
  usable = SelectReferenceViews(rec, geoms, all_usable, options.references);
  std::map<uint32_t, ReferenceSelection> reference_selection;
  const auto* fusion_selection = &selection;
  if (usable.size() < all_usable.size()) {
    std::map<uint32_t, ViewGeometry> ref_geoms;
    for (uint32_t id : usable) ref_geoms[id] = geoms.at(id);
    reference_selection = SelectViews(rec, ref_geoms, options.selection);
    fusion_selection = &reference_selection;
    spdlog::info("dense: {} of {} views are references (each sparse point in {} of them)", usable.size(),
                 all_usable.size(), options.references.coverage);
  }
  core::EnsureDirectory(maps_dir);
  core::EnsureDirectory(report_dir);
  ViewCache cache(rec, geoms, frames_dir, static_cast<size_t>(std::max(options.cache_views, options.max_sources + 2)));
  auto sources_of = [&](uint32_t id) {
    std::vector<uint32_t> s;
    for (const auto& nb : selection.at(id).neighbours) {
      if (static_cast<int>(s.size()) >= options.max_sources) break;
      s.push_back(nb.image_id);
    }
    return s;
  };
  auto map_path = [&](uint32_t id, const char* suffix) { return maps_dir / (MapFileStem(geoms.at(id).name) + suffix); };
  std::map<uint32_t, std::vector<Eigen::Vector3d>> seeds;
  for (const auto& [pid, p] : rec.points)
    for (const auto& te : p.track) seeds[te.image_id].push_back(p.xyz);

  if (options.fuse_only)
    for (uint32_t id : usable)
      if (!fs::exists(map_path(id, ".dmap")))
        throw Error(map_path(id, ".dmap").string() + ": no depth map to fuse — run `fmv3d dense` without --fuse-only");

  // --- Photometric pass.
  const auto t_photo = Clock::now();
  double pm_seconds = 0;
  if (!options.fuse_only) {
    core::Progress progress("dense: photometric depth maps", usable.size());
    for (uint32_t id : usable) {
      PatchMatchInput in;
      const auto ref = cache.Get(id);
      std::vector<std::shared_ptr<const View>> holds;
      for (uint32_t s : sources_of(id)) holds.push_back(cache.Get(s));
      in.ref = ref.get();
      for (const auto& h : holds) in.sources.push_back(h.get());
      in.depth_min = selection.at(id).depth_min;
      in.depth_max = selection.at(id).depth_max;
      if (auto it = seeds.find(id); it != seeds.end()) in.seeds = it->second;
      PatchMatchStats st;
      const DepthMap map = RunPatchMatch(in, options.patch_match, &st);
      pm_seconds += st.seconds;
      WriteDepthMap(map, options.geometric ? map_path(id, ".photometric.dmap") : map_path(id, ".dmap"));
      spdlog::debug("dense: {} photometric: {} valid pixels in {:.2f} s", geoms.at(id).name, st.valid_pixels,
                    st.seconds);
      progress.Add();
    }
  }
  const double photo_seconds = seconds_since(t_photo);

  // --- Geometric-consistency pass.
  const auto t_geom = Clock::now();
  double geom_pm_seconds = 0;
  if (options.geometric && !options.fuse_only) {
    core::Progress progress("dense: geometric depth maps", usable.size());
    const std::set<uint32_t> usable_set(usable.begin(), usable.end());
    for (uint32_t id : usable) {
      const DepthMap init = ReadDepthMap(map_path(id, ".photometric.dmap"));
      PatchMatchInput in;
      const auto ref = cache.Get(id);
      std::vector<std::shared_ptr<const View>> holds;
      std::vector<DepthMap> src_maps;
      const auto src_ids = sources_of(id);
      src_maps.reserve(src_ids.size());
      for (uint32_t s : src_ids) {
        holds.push_back(cache.Get(s));
        src_maps.push_back(usable_set.count(s) ? ReadDepthMap(map_path(s, ".photometric.dmap")) : DepthMap{});
      }
      in.ref = ref.get();
      for (size_t k = 0; k < holds.size(); ++k) {
        in.sources.push_back(holds[k].get());
        in.source_maps.push_back(src_maps[k].empty() ? nullptr : &src_maps[k]);
      }
      in.depth_min = selection.at(id).depth_min;
      in.depth_max = selection.at(id).depth_max;
      in.init = &init;
      PatchMatchStats st;
      const DepthMap map = RunPatchMatch(in, options.patch_match, &st);
      geom_pm_seconds += st.seconds;
      WriteDepthMap(map, map_path(id, ".dmap"));
      progress.Add();
    }
    if (!options.keep_photometric)
      for (uint32_t id : usable) fs::remove(map_path(id, ".photometric.dmap"));
  }
  const double geom_seconds = seconds_since(t_geom);

  // --- Fusion (+ previews while the maps are read).
  const auto t_fuse = Clock::now();
  std::map<uint32_t, FusionView> fviews;
  std::map<uint32_t, std::set<uint32_t>> links;
  for (uint32_t id : usable)
    for (const auto& nb : fusion_selection->at(id).neighbours) {
      links[id].insert(nb.image_id);
      links[nb.image_id].insert(id);  // symmetric: a view checks every view that chose it too
    }
  size_t valid_pixels = 0, total_pixels = 0;
  {
    core::Progress progress("dense: loading maps for fusion", usable.size());
    for (uint32_t id : usable) {
      const DepthMap map = ReadDepthMap(map_path(id, ".dmap"));
      if (options.previews && !options.fuse_only)
        WriteDepthPreview(map, map_path(id, ".depth.png"), map_path(id, ".normal.png"));
      valid_pixels += static_cast<size_t>(map.CountValid());
      total_pixels += map.depth.total();
      const auto view = cache.Get(id);
      FusionView fv =
          MakeFusionView(geoms.at(id), map, view->color, std::vector<uint32_t>(links[id].begin(), links[id].end()));
      if (options.fusion.max_relative_uncertainty > 0)
        fv.texture = TexturePrecisionMap(view->color, options.patch_match.window_radius);
      fviews.emplace(id, std::move(fv));
      progress.Add();
    }
  }
  FusionStats fstats;
  // Straight to the PLY: the cloud is never held in memory (the largest part of the stage's memory otherwise).
  const size_t n_points = FuseDepthMapsToPly(std::move(fviews), options.fusion, dense_dir / "fused.ply", &fstats);
  fviews.clear();
  if (n_points == 0)
    spdlog::warn("dense: fusion produced no points (no pixel was consistent in {} views)", options.fusion.min_views);
  const double fuse_seconds = seconds_since(t_fuse);

  nlohmann::json hist = nlohmann::json::object();
  double mean_views = 0;
  for (const auto& [k, n] : fstats.views_histogram) {
    hist[std::to_string(k)] = n;
    mean_views += static_cast<double>(k) * n;
  }
  if (n_points > 0) mean_views /= static_cast<double>(n_points);
  const auto& g0 = geoms.at(usable.front());
  nlohmann::json report = {
      {"registered_images", rec.images.size()},
      {"views_used", all_usable.size()},
      {"reference_views", usable.size()},
      {"reference_coverage", options.references.coverage},
      {"views_skipped", skipped},
      {"working_resolution", {g0.width, g0.height}},
      {"max_size", options.max_size},
      {"max_sources", options.max_sources},
      {"geometric_pass", options.geometric},
      {"points", n_points},
      {"valid_depth_fraction", total_pixels ? static_cast<double>(valid_pixels) / total_pixels : 0.0},
      {"fusion",
       {{"candidates", fstats.candidates},
        {"rejected_too_few_views", fstats.rejected_support},
        {"rejected_visibility", fstats.rejected_visibility},
        {"edge_pixels_removed", fstats.edge_pixels},
        {"edge_erosion_px", options.fusion.edge_erosion_px},
        {"rejected_uncertainty", fstats.rejected_uncertainty},
        {"max_relative_uncertainty", options.fusion.max_relative_uncertainty},
        {"median_normal_sigma", fstats.median_uncertainty},
        {"max_normal_sigma", fstats.max_uncertainty},
        {"sigma_scale", fstats.sigma_scale},
        {"sigma_coverage",
         options.fusion.write_sigma ? nlohmann::json(options.fusion.sigma_coverage) : nlohmann::json()},
        {"mean_consistent_views", mean_views},
        {"consistent_views_histogram", hist}}},
      {"seconds",
       {{"view_selection", sel_seconds},
        {"load_undistort", cache.load_seconds()},
        {"photometric", photo_seconds},
        {"photometric_per_view", pm_seconds / usable.size()},
        {"geometric", geom_seconds},
        {"geometric_per_view", options.geometric ? geom_pm_seconds / usable.size() : 0.0},
        {"fusion", fuse_seconds},
        {"total", seconds_since(t_start)}}},
      {"output", (dense_dir / "fused.ply").string()}};
  core::WriteJson(report_dir / "dense.json", report);
  spdlog::info("dense: {} points from {} views ({} skipped) in {:.1f} s", n_points, usable.size(), skipped.size(),
               seconds_since(t_start));
  return report;
}

}  // namespace fmv3d::mvs
