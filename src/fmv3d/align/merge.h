// Merging aligned mission tracks into one workspace (the `fmv3d align` stage).
//
//   WS_MERGED/sparse/           COLMAP text model: every track's cameras, registered images and points, moved
//                               into the reference track's frame (ids renumbered: reference first); sparse.ply
//   WS_MERGED/frames/           the images of every registered frame (hard links when possible, else copies)
//                               and frames.json (camera priors and frame records of all tracks, renumbered)
//   WS_MERGED/dense/fused.ply   when every track has a dense cloud: by default, multi-view stereo run again
//                               over the merged model (every track's views are stereo partners of every
//                               other's; settings from the tracks' report/dense.json, see
//                               MergedDenseOptions), so surface seen by several tracks is triangulated from
//                               all of them. With recompute_dense off, or when that run fails: the union of
//                               the tracks' clouds in the reference frame, visibility lists re-mapped to the
//                               merged image ids (only when at least one track has one)
//   WS_MERGED/report/align.json the similarities, overlap, inliers, residual RMS before / after per pair, and
//                               the joint bundle adjustment's reprojection RMS before / after
// Joint bundle adjustment (optional, on by default): the cross-track 3D–3D links the coarse alignment found
// consistent are fused into single points (when their reprojection errors in every image of both tracks stay
// small at the midpoint), then one bundle adjustment refines every camera, intrinsics and point of all
// tracks together; the reference track's first two images fix the gauge, so the result stays in its frame.
// Each track's dense cloud follows its cameras: the similarity of its camera centres before → after the
// adjustment is applied to its points (dense clouds are not recomputed).
// Frame names are kept unless two tracks share a name (e.g. two synthetic flights): then every image of a
// non-reference track is renamed "<track name>-<name>".
// Nothing is written unless the alignment succeeded.
#pragma once

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/align/tracks.h"
#include "fmv3d/mvs/dense_stage.h"

namespace fmv3d::align {

struct MergedModel {
  core::Reconstruction sparse;
  io::OrientedPointCloud dense;  // empty when no track has a dense cloud
  // Per track: old image id → merged image id, and old image name → merged name.
  std::vector<std::map<uint32_t, uint32_t>> image_ids;
  std::vector<std::map<std::string, std::string>> image_names;
  std::vector<std::map<uint32_t, uint32_t>> camera_ids;
  std::vector<std::map<uint64_t, uint64_t>> point_ids;  // per track: old 3D point id → merged id
  std::vector<std::pair<size_t, size_t>> dense_ranges;  // per track: [begin, end) in `dense`
  std::vector<std::string> name_prefix;                 // per track, "" when its names are kept
};

// The images of a merged model split by a track's name prefix (e.g. "B-"): .first the images without it, .second
// those with it under their original names; cameras copied, no points. Lets each track's part be checked
// against that track's own ground truth.
std::pair<core::Reconstruction, core::Reconstruction> SplitByNamePrefix(const core::Reconstruction& merged,
                                                                        const std::string& prefix);

// Moves every track by alignment.to_reference and unions the models (see the header comment).
MergedModel MergeTracks(const std::vector<Track>& tracks, const MultiTrackAlignment& alignment);

struct JointAdjustmentResult {
  size_t links = 0, links_fused = 0;  // cross-track 3D links offered / fused into one point
  int iterations = 0;
  double rms_before_px = 0, rms_after_px = 0;  // reprojection RMS of all observations
  double seconds = 0;
  std::vector<core::Sim3> track_motion;  // per track: camera centres before → after (applied to its dense points)
  nlohmann::json ToJson() const;
};

// Fuses the cross-track links of the alignment tree in `merged` and bundle-adjusts all tracks together
// (see the header comment). max_link_error_px: a link is fused only when every observation of the fused
// point reprojects within this many pixels. Throws fmv3d::Error when the adjustment fails.
JointAdjustmentResult JointBundleAdjust(MergedModel* merged, const MultiTrackAlignment& alignment,
                                        double max_link_error_px = 4.0);

// Where two tracks' dense clouds cover the same surface, keeps the finer one: a point is dropped when another
// track has a point within `radius_spacings` of its own cloud's median spacing whose footprint (the finest
// pixel size on the surface among the cameras that see it: distance / focal) is smaller. Both surfaces stay
// where only one track saw them. Needs visibility lists (the dense stage writes them); returns points dropped.
size_t KeepFinerInOverlap(MergedModel* merged, double radius_spacings = 2.0);

struct MergeOptions {
  bool joint_bundle_adjustment = true;
  // Re-run the dense stage on the merged workspace (needs every track's dense cloud); false: union of the
  // tracks' clouds. Measured on two 200° arcs (bench/RESULTS.md): the union's median error lies
  // between the two tracks' (it mixes the worse track in where both see the surface); the recomputed cloud is
  // at least as accurate as the better track, median and p90, and as complete as the union.
  bool recompute_dense = true;
  double max_link_error_px = 4.0;
  bool keep_finer_in_overlap = false;
};

// Dense settings for the merged workspace from the tracks' report/dense.json: the finest working size (0 =
// full frames wins), the most source views, the geometric pass and reference cover if any track used them;
// no previews. Everything else at mvs::DenseStageOptions' defaults.
mvs::DenseStageOptions MergedDenseOptions(const std::vector<Track>& tracks);

// `fmv3d align WS_A WS_B ... -o WS_MERGED`: load, align, merge, write. Returns the report (also written to
// WS_MERGED/report/align.json). Throws fmv3d::Error — writing nothing — when a track cannot be loaded or
// overlaps no other ("no overlap found between A and B").
nlohmann::json RunAlignStage(const std::vector<std::filesystem::path>& workspaces, const std::filesystem::path& output,
                             const TrackAlignOptions& options, const MergeOptions& merge_options = {});

}  // namespace fmv3d::align
