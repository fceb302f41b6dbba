// Merging aligned mission tracks into one workspace (the `fmv3d align` stage).
//
//   WS_MERGED/sparse/           COLMAP text model: every track's cameras, registered images and points, moved
//                               into the reference track's frame (ids renumbered: reference first); sparse.ply
//   WS_MERGED/frames/           the images of every registered frame (hard links when possible, else copies)
//                               and frames.json (camera priors and frame records of all tracks, renumbered)
//   WS_MERGED/dense/fused.ply   union of the tracks' dense clouds in the reference frame, visibility lists
//                               re-mapped to the merged image ids (only when at least one track has one)
//   WS_MERGED/report/align.json the similarities, overlap, inliers, residual RMS before / after per pair
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

namespace fmv3d::align {

struct MergedModel {
  core::Reconstruction sparse;
  io::OrientedPointCloud dense;  // empty when no track has a dense cloud
  // Per track: old image id → merged image id, and old image name → merged name.
  std::vector<std::map<uint32_t, uint32_t>> image_ids;
  std::vector<std::map<std::string, std::string>> image_names;
  std::vector<std::map<uint32_t, uint32_t>> camera_ids;
  std::vector<std::string> name_prefix;  // per track, "" when its names are kept
};

// Moves every track by alignment.to_reference and unions the models (see the header comment).
MergedModel MergeTracks(const std::vector<Track>& tracks, const MultiTrackAlignment& alignment);

// `fmv3d align WS_A WS_B ... -o WS_MERGED`: load, align, merge, write. Returns the report (also written to
// WS_MERGED/report/align.json). Throws fmv3d::Error — writing nothing — when a track cannot be loaded or
// overlaps no other ("no overlap found between A and B").
nlohmann::json RunAlignStage(const std::vector<std::filesystem::path>& workspaces,
                             const std::filesystem::path& output, const TrackAlignOptions& options);

}  // namespace fmv3d::align
