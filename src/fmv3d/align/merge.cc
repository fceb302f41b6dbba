#include "fmv3d/align/merge.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <optional>
#include <set>

#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geometry/similarity.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/sfm/bundle_adjustment.h"
#include "fmv3d/sfm/sparse_stage.h"

namespace fmv3d::align {
namespace {

namespace fs = std::filesystem;

// Reference first, then the others in the order given.
std::vector<size_t> MergeOrder(size_t n, size_t reference) {
  std::vector<size_t> order = {reference};
  for (size_t k = 0; k < n; ++k)
    if (k != reference) order.push_back(k);
  return order;
}

// Per track, the prefix its image names get ("" = unchanged): only when some name occurs in two tracks.
std::vector<std::string> NamePrefixes(const std::vector<Track>& tracks, size_t reference) {
  std::map<std::string, int> count;
  for (const auto& t : tracks) {
    std::set<std::string> names;
    for (const auto& [id, im] : t.sparse.images) names.insert(im.name);
    for (const auto& n : names) ++count[n];
  }
  bool clash = false;
  for (const auto& [n, c] : count) clash |= c > 1;
  std::vector<std::string> prefix(tracks.size());
  if (!clash) return prefix;
  std::set<std::string> used;
  for (size_t k = 0; k < tracks.size(); ++k) {
    if (k == reference) continue;
    std::string p = tracks[k].name.empty() ? "track" : tracks[k].name;
    if (!used.insert(p).second) p += "_" + std::to_string(k);
    used.insert(p);
    prefix[k] = p + "-";
  }
  return prefix;
}

void LinkOrCopy(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::create_directories(to.parent_path(), ec);
  fs::remove(to, ec);
  fs::create_hard_link(from, to, ec);
  if (ec) {
    ec.clear();
    fs::copy_file(from, to, fs::copy_options::overwrite_existing, ec);
    if (ec) throw Error(to.string() + ": cannot copy " + from.string() + ": " + ec.message());
  }
}

}  // namespace

MergedModel MergeTracks(const std::vector<Track>& tracks, const MultiTrackAlignment& alignment) {
  if (alignment.to_reference.size() != tracks.size()) throw Error("merge: alignment does not match the tracks");
  MergedModel m;
  m.image_ids.resize(tracks.size());
  m.image_names.resize(tracks.size());
  m.camera_ids.resize(tracks.size());
  m.point_ids.resize(tracks.size());
  m.dense_ranges.assign(tracks.size(), {0, 0});
  const auto prefix = NamePrefixes(tracks, alignment.reference);
  m.name_prefix = prefix;
  uint32_t next_camera = 1, next_image = 1;
  uint64_t next_point = 1;
  for (size_t k : MergeOrder(tracks.size(), alignment.reference)) {
    core::Reconstruction rec = tracks[k].sparse;
    rec.Transform(alignment.to_reference[k]);
    for (auto& [id, cam] : rec.cameras) {
      m.camera_ids[k][id] = next_camera;
      cam.id = next_camera;
      m.sparse.cameras[next_camera++] = cam;
    }
    std::map<uint64_t, uint64_t>& point_ids = m.point_ids[k];
    for (const auto& [id, pt] : rec.points) point_ids[id] = next_point++;
    for (auto& [id, im] : rec.images) {
      m.image_ids[k][id] = next_image;
      m.image_names[k][im.name] = prefix[k] + im.name;
      core::Image out = im;
      out.id = next_image;
      out.camera_id = m.camera_ids[k].at(im.camera_id);
      out.name = prefix[k] + im.name;
      for (auto& p : out.point3d_ids)
        if (p != core::kNoPoint3D) {
          const auto it = point_ids.find(static_cast<uint64_t>(p));
          p = it == point_ids.end() ? core::kNoPoint3D : static_cast<int64_t>(it->second);
        }
      m.sparse.images[next_image++] = std::move(out);
    }
    for (const auto& [id, pt] : rec.points) {
      core::Point3D out = pt;
      out.id = point_ids.at(id);
      for (auto& el : out.track) el.image_id = m.image_ids[k].at(el.image_id);
      m.sparse.points[out.id] = std::move(out);
    }
    // Dense points: moved, normals rotated, visibility re-mapped (ids unknown to the sparse model dropped).
    const io::OrientedPointCloud& d = tracks[k].dense;
    if (d.empty()) continue;
    const core::Sim3& T = alignment.to_reference[k];
    io::OrientedPointCloud moved;
    moved.positions.reserve(d.size());
    for (const auto& p : d.positions) moved.positions.push_back(T.Apply(p));
    if (d.has_normals())
      for (const auto& n : d.normals) moved.normals.push_back((T.q.cast<float>() * n).normalized());
    moved.colors = d.colors;
    if (d.has_visibility()) {
      moved.visibility.resize(d.size());
      for (size_t i = 0; i < d.size(); ++i)
        for (uint32_t id : d.visibility[i]) {
          const auto it = m.image_ids[k].find(id);
          if (it != m.image_ids[k].end()) moved.visibility[i].push_back(it->second);
        }
    }
    m.dense_ranges[k] = {m.dense.size(), m.dense.size() + moved.size()};
    m.dense.Append(moved);
  }
  return m;
}

std::pair<core::Reconstruction, core::Reconstruction> SplitByNamePrefix(const core::Reconstruction& merged,
                                                                        const std::string& prefix) {
  std::pair<core::Reconstruction, core::Reconstruction> parts;
  parts.first.cameras = parts.second.cameras = merged.cameras;
  for (const auto& [id, im] : merged.images) {
    core::Image copy = im;
    copy.point3d_ids.assign(copy.points2d.size(), core::kNoPoint3D);  // the points are not copied
    if (!prefix.empty() && im.name.rfind(prefix, 0) == 0) {
      copy.name = im.name.substr(prefix.size());
      parts.second.images[id] = std::move(copy);
    } else {
      parts.first.images[id] = std::move(copy);
    }
  }
  return parts;
}

size_t KeepFinerInOverlap(MergedModel* merged, double radius_spacings) {
  io::OrientedPointCloud& d = merged->dense;
  if (!d.has_visibility()) return 0;
  const core::Reconstruction& rec = merged->sparse;
  std::vector<double> footprint(d.size(), std::numeric_limits<double>::infinity());
  for (size_t i = 0; i < d.size(); ++i)
    for (uint32_t id : d.visibility[i]) {
      const auto it = rec.images.find(id);
      if (it == rec.images.end()) continue;
      const double f = rec.cameras.at(it->second.camera_id).f;
      footprint[i] = std::min(footprint[i], (d.positions[i] - it->second.pose.Centre()).norm() / f);
    }
  struct Part {
    size_t begin, end;
    std::unique_ptr<PointIndex> index;
    double radius;
  };
  std::vector<Part> parts;
  for (const auto& [begin, end] : merged->dense_ranges) {
    if (end - begin < 2) continue;
    std::vector<Eigen::Vector3d> pts(d.positions.begin() + begin, d.positions.begin() + end);
    auto index = std::make_unique<PointIndex>(pts);
    const double r = radius_spacings * MedianSpacing(pts, *index);
    parts.push_back({begin, end, std::move(index), r});
  }
  std::vector<char> drop(d.size(), 0);
  for (const auto& own : parts)
    tbb::parallel_for(tbb::blocked_range<size_t>(own.begin, own.end), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i)
        for (const auto& other : parts) {
          if (&other == &own) continue;
          double d2 = 0;
          const int j = other.index->Nearest(d.positions[i], &d2);
          if (j >= 0 && d2 <= own.radius * own.radius && footprint[other.begin + j] < footprint[i]) {
            drop[i] = 1;
            break;
          }
        }
    });
  io::OrientedPointCloud kept;
  std::vector<std::pair<size_t, size_t>> ranges;
  for (const auto& [begin, end] : merged->dense_ranges) {
    const size_t start = kept.positions.size();
    for (size_t i = begin; i < end; ++i) {
      if (drop[i]) continue;
      kept.positions.push_back(d.positions[i]);
      if (d.has_normals()) kept.normals.push_back(d.normals[i]);
      if (d.has_colors()) kept.colors.push_back(d.colors[i]);
      kept.visibility.push_back(d.visibility[i]);
    }
    ranges.push_back({start, kept.positions.size()});
  }
  const size_t dropped = d.size() - kept.size();
  d = std::move(kept);
  merged->dense_ranges = ranges;
  spdlog::info("align: {} dense points dropped where a finer track covers the same surface", dropped);
  return dropped;
}

nlohmann::json JointAdjustmentResult::ToJson() const {
  nlohmann::json motion = nlohmann::json::array();
  for (const auto& s : track_motion) motion.push_back(Sim3ToJson(s));
  return {{"links", links},
          {"links_fused", links_fused},
          {"iterations", iterations},
          {"reprojection_rms_before_px", rms_before_px},
          {"reprojection_rms_after_px", rms_after_px},
          {"seconds", seconds},
          {"track_motion", motion}};
}

JointAdjustmentResult JointBundleAdjust(MergedModel* merged, const MultiTrackAlignment& alignment,
                                        double max_link_error_px) {
  core::Reconstruction& rec = merged->sparse;
  JointAdjustmentResult res;
  // 1. Fuse each link (one-to-one) into the reference-side point, at the midpoint of the two.
  std::set<uint64_t> used;
  for (const auto& edge : alignment.tree)
    for (const auto& [ra, mb] : edge.links) {
      ++res.links;
      const auto ia = merged->point_ids[edge.reference].find(ra);
      const auto ib = merged->point_ids[edge.moving].find(mb);
      if (ia == merged->point_ids[edge.reference].end() || ib == merged->point_ids[edge.moving].end()) continue;
      const uint64_t pa = ia->second, pb = ib->second;
      if (used.count(pa) || used.count(pb) || !rec.points.count(pa) || !rec.points.count(pb)) continue;
      core::Point3D& a = rec.points.at(pa);
      const core::Point3D& b = rec.points.at(pb);
      const Eigen::Vector3d mid = 0.5 * (a.xyz + b.xyz);
      bool ok = true;
      for (const core::Point3D* p : {static_cast<const core::Point3D*>(&a), &b})
        for (const auto& el : p->track)
          ok = ok && sfm::ObservationError(rec, el.image_id, el.point2d_idx, mid) <= max_link_error_px;
      if (!ok) continue;
      used.insert(pa);
      used.insert(pb);
      a.xyz = mid;
      for (const auto& el : b.track) {
        a.track.push_back(el);
        rec.images.at(el.image_id).point3d_ids[el.point2d_idx] = static_cast<int64_t>(pa);
      }
      rec.points.erase(pb);
      ++res.links_fused;
    }
  spdlog::info("align: joint bundle adjustment, {} of {} cross-track links fused", res.links_fused, res.links);

  // 2. One bundle adjustment of everything; the gauge is the two lowest image ids (the reference track's).
  std::map<uint32_t, Eigen::Vector3d> before;
  for (const auto& [id, im] : rec.images) before[id] = im.pose.Centre();
  sfm::BundleAdjustmentOptions bo;
  bo.max_iterations = 50;
  const sfm::BundleAdjustmentSummary s = sfm::BundleAdjust(&rec, sfm::BundleAdjustmentConfig{}, bo);
  if (!s.success) throw Error("align: the joint bundle adjustment failed");
  res.iterations = s.num_iterations;
  res.rms_before_px = s.initial_rms_px;
  res.rms_after_px = s.final_rms_px;
  res.seconds = s.seconds;

  // 3. Each track's dense points follow its cameras.
  res.track_motion.assign(merged->image_ids.size(), core::Sim3());
  for (size_t k = 0; k < merged->image_ids.size(); ++k) {
    std::vector<Eigen::Vector3d> src, dst;
    for (const auto& [old_id, id] : merged->image_ids[k]) {
      src.push_back(before.at(id));
      dst.push_back(rec.images.at(id).pose.Centre());
    }
    core::Sim3 motion;
    if (src.size() < 3 || !geometry::EstimateSimilarity(src, dst, {}, true, &motion)) continue;
    res.track_motion[k] = motion;
    const auto [begin, end] = merged->dense_ranges[k];
    const Eigen::Quaternionf q = motion.q.cast<float>();
    for (size_t i = begin; i < end; ++i) {
      merged->dense.positions[i] = motion.Apply(merged->dense.positions[i]);
      if (merged->dense.has_normals()) merged->dense.normals[i] = (q * merged->dense.normals[i]).normalized();
    }
  }
  spdlog::info("align: joint bundle adjustment {} iterations, reprojection RMS {:.3f} → {:.3f} px", res.iterations,
               res.rms_before_px, res.rms_after_px);
  return res;
}

mvs::DenseStageOptions MergedDenseOptions(const std::vector<Track>& tracks) {
  mvs::DenseStageOptions o;
  o.previews = false;
  bool seen = false, full = false, geometric = false;
  int max_size = 0, max_sources = 0, coverage = 0;
  for (const auto& t : tracks) {
    if (!t.dense_settings) continue;
    const DenseSettings& d = *t.dense_settings;
    seen = true;
    if (d.max_size == 0) full = true;
    max_size = std::max(max_size, d.max_size);
    max_sources = std::max(max_sources, d.max_sources);
    geometric = geometric || d.geometric_pass;
    coverage = std::max(coverage, d.reference_coverage);
  }
  if (!seen) return o;
  o.max_size = full ? 0 : max_size;
  o.max_sources = max_sources;
  o.geometric = geometric;
  o.references.coverage = coverage;
  return o;
}

namespace {

// Links each track's frames into the output under their merged names and writes the merged frames.json.
struct FramesWritten {
  size_t linked = 0, missing = 0;
};

FramesWritten WriteMergedFrames(const std::vector<Track>& tracks, const MultiTrackAlignment& alignment,
                                const MergedModel& merged, const core::Workspace& out) {
  io::FramesIndex index;
  FramesWritten n;
  for (size_t k : MergeOrder(tracks.size(), alignment.reference)) {
    const core::Workspace in_ws(tracks[k].workspace);
    const fs::path frames = in_ws.frames_dir();
    for (const auto& [old_name, new_name] : merged.image_names[k]) {
      if (fs::exists(frames / old_name)) {
        LinkOrCopy(frames / old_name, out.frames_dir() / new_name);
        ++n.linked;
      } else {
        ++n.missing;
      }
    }
    if (!fs::exists(in_ws.frames_json())) continue;
    const io::FramesIndex in = io::ReadFramesIndex(in_ws.frames_json());
    for (const auto& cam : in.cameras) {
      const auto it = merged.camera_ids[k].find(cam.camera.id);
      if (it == merged.camera_ids[k].end()) continue;
      io::CameraPrior c = cam;
      c.camera.id = it->second;
      index.cameras.push_back(c);
    }
    for (const auto& f : in.frames) {
      const auto it = merged.image_names[k].find(f.name);
      const auto cit = merged.camera_ids[k].find(f.camera_id);
      if (it == merged.image_names[k].end() || cit == merged.camera_ids[k].end()) continue;
      io::FrameRecord r = f;
      r.name = it->second;
      r.camera_id = cit->second;
      index.frames.push_back(r);
    }
  }
  if (!index.frames.empty()) io::WriteFramesIndex(index, out.frames_json());
  if (n.missing) spdlog::warn("align: {} frame images not found in the input workspaces", n.missing);
  return n;
}

// The merged dense cloud: multi-view stereo again over every track's views when each track has a dense cloud and
// all frames are there, else (or when that fails) the union of the tracks' clouds. Returns its report block.
nlohmann::json WriteMergedDense(const std::vector<Track>& tracks, const MergedModel& merged, bool frames_complete,
                                const MergeOptions& merge_options, const fs::path& output) {
  nlohmann::json dense_json = {{"method", "none"}};
  if (merged.dense.empty()) return dense_json;
  const bool every_track_dense =
      std::all_of(tracks.begin(), tracks.end(), [](const Track& t) { return !t.dense.empty(); });
  if (merge_options.recompute_dense && every_track_dense && frames_complete) {
    const mvs::DenseStageOptions dense_options = MergedDenseOptions(tracks);
    spdlog::info("align: multi-view stereo over the merged model ({} views, {} px)", merged.sparse.images.size(),
                 dense_options.max_size);
    try {
      const nlohmann::json r = mvs::RunDenseStage(output, dense_options);
      return {{"method", "recomputed over every track's views"},
              {"points", r.at("points")},
              {"max_size", dense_options.max_size},
              {"max_sources", dense_options.max_sources},
              {"geometric_pass", dense_options.geometric},
              {"reference_coverage", dense_options.references.coverage}};
    } catch (const Error& e) {
      spdlog::warn(
          "align: multi-view stereo over the merged model failed ({}); writing the union of the "
          "tracks' dense clouds instead",
          e.what());
      dense_json = {{"method", "union"}, {"recompute_failed", e.what()}};
    }
  } else {
    dense_json = {{"method", "union"}};
    if (merge_options.recompute_dense)
      dense_json["why_not_recomputed"] =
          !every_track_dense ? "a track has no dense cloud" : "frame images of the tracks are missing";
  }
  const core::Workspace out(output);
  core::EnsureDirectory(out.dense_dir());
  io::WritePointCloudPly(merged.dense, out.dense_dir() / "fused.ply");
  dense_json["points"] = merged.dense.size();
  return dense_json;
}

}  // namespace

nlohmann::json RunAlignStage(const std::vector<fs::path>& workspaces, const fs::path& output,
                             const TrackAlignOptions& options, const MergeOptions& merge_options) {
  options.Check();
  if (workspaces.size() < 2) throw Error("align: give at least two workspaces");
  for (const auto& ws : workspaces)
    if (fs::exists(output) && fs::exists(ws) && fs::equivalent(ws, output))
      throw Error("align: the output " + output.string() + " is one of the inputs");
  std::vector<Track> tracks;
  tracks.reserve(workspaces.size());
  for (const auto& ws : workspaces) tracks.push_back(LoadTrack(ws));
  const MultiTrackAlignment alignment = AlignTracks(tracks, options);
  MergedModel merged = MergeTracks(tracks, alignment);
  merged.sparse.Validate();
  std::optional<JointAdjustmentResult> joint;
  if (merge_options.joint_bundle_adjustment) {
    joint = JointBundleAdjust(&merged, alignment, merge_options.max_link_error_px);
    merged.sparse.Validate();
  }
  const size_t dense_before_overlap = merged.dense.size();
  const size_t overlap_dropped = merge_options.keep_finer_in_overlap ? KeepFinerInOverlap(&merged) : 0;

  // Everything is computed: write.
  const core::Workspace out(output);
  core::EnsureDirectory(out.sparse_dir());
  io::WriteColmapText(merged.sparse, out.sparse_dir());
  sfm::WritePointsPly(merged.sparse, out.sparse_dir() / "sparse.ply");
  const FramesWritten frames = WriteMergedFrames(tracks, alignment, merged, out);
  const nlohmann::json dense_json = WriteMergedDense(tracks, merged, frames.missing == 0, merge_options, output);

  nlohmann::json report;
  report["reference"] = tracks[alignment.reference].name;
  for (size_t k = 0; k < tracks.size(); ++k) {
    const auto& t = tracks[k];
    report["tracks"].push_back({{"name", t.name},
                                {"workspace", t.workspace.string()},
                                {"images", t.sparse.images.size()},
                                {"points", t.sparse.points.size()},
                                {"dense_points", t.dense.size()},
                                {"to_reference", Sim3ToJson(alignment.to_reference[k])},
                                {"to_reference_after_joint_ba",
                                 Sim3ToJson(joint ? ComposeSim3(joint->track_motion[k], alignment.to_reference[k])
                                                  : alignment.to_reference[k])},
                                {"image_name_prefix", merged.name_prefix[k]}});
  }
  for (const auto& p : alignment.pairs) report["pairs"].push_back(p.ToJson(tracks));
  for (const auto& p : alignment.tree) report["tree"].push_back(p.ToJson(tracks));
  report["merged"] = {{"cameras", merged.sparse.cameras.size()},
                      {"images", merged.sparse.images.size()},
                      {"points", merged.sparse.points.size()},
                      {"dense_points", dense_json.value("points", size_t{0})},
                      {"dense_points_union", dense_before_overlap},
                      {"dense_points_dropped_in_overlap", overlap_dropped},
                      {"frames_linked", frames.linked},
                      {"frames_missing", frames.missing}};
  report["dense"] = dense_json;
  if (joint) report["joint_bundle_adjustment"] = joint->ToJson();
  report["notes"] =
      "residual_rms_*: fine step 'correspondences' — RMS of the inlier 3D-3D distances with the RANSAC model "
      "(before) and the robust refit (after); 'icp-dense' — ICP point-to-plane RMS at the start and end. "
      "Units of the reference model.";
  core::EnsureDirectory(out.report_dir());
  core::WriteJson(out.report_dir() / "align.json", report);
  return report;
}

}  // namespace fmv3d::align
