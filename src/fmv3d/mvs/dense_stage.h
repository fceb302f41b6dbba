// The `fmv3d dense WS` stage: WS/sparse (COLMAP text model) + WS/frames → dense oriented points.
//   1. every registered frame is undistorted and scaled to the working resolution (streamed from disk,
//      a bounded cache of views in memory);
//   2. global view selection picks each view's stereo sources and fusion neighbours, and (optionally) the
//      reference views that get a depth map (view_selection.h);
//   3. PatchMatch photometric pass per view, then a geometric-consistency pass using the neighbours' maps
//      (patch_match.h);
//   4. fusion of the filtered maps into oriented points (fusion.h).
// Outputs:
//   WS/dense/maps/<image name>.dmap            final depth/normal/cost map (depth_map.h format)
//   WS/dense/maps/<image name>.depth.png       false-colour depth; .normal.png normals
//   WS/dense/fused.ply                         oriented points with visibility lists (io/point_cloud.h)
//   WS/report/dense.json                       views used / skipped (with reasons), points, time per stage
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/workspace.h"
#include "fmv3d/mvs/fusion.h"
#include "fmv3d/mvs/patch_match.h"
#include "fmv3d/mvs/view_selection.h"

namespace fmv3d::mvs {

struct DenseStageOptions {
  int max_size = 960;             // working resolution: longer image side, pixels (0 = full frames)
  int max_sources = 5;            // stereo source views per reference
  bool geometric = true;          // run the geometric-consistency pass
  bool previews = true;           // write the PNG previews of every map
  bool keep_photometric = false;  // keep the photometric-pass maps (<name>.photometric.dmap)
  int cache_views = 16;           // undistorted views kept in memory
  // Memory for the views held at once: the undistorted-view cache (cache_views) and fusion's window of maps
  // (fusion_window.h) get this between them; fusion then holds as many maps as fit (at least a reference with its
  // neighbours), so the number of frames does not set the stage's memory.
  double max_memory_mb = 2048;
  // Depth maps only for a subset of views that sees every sparse point reference_coverage times
  // (SelectReferenceViews); the others are stereo sources only.
  ReferenceCoverOptions references;  // .coverage 0 = a map for every view
  bool fuse_only = false;  // reuse the final maps already in WS/dense/maps (e.g. to re-fuse with other options)
  ViewSelectionOptions selection;
  PatchMatchOptions patch_match;
  FusionOptions fusion;
  void Check() const;
};

// Returns the summary also written to WS/report/dense.json. Throws fmv3d::Error when WS/sparse is missing,
// has fewer than two registered images, or no view has a usable neighbour; single views without a usable
// neighbour are skipped with a warning (and listed in the report).
nlohmann::json RunDenseStage(const core::Workspace& workspace, const DenseStageOptions& options);

// File name of a view's map in WS/dense/maps ("a/b.png" → "a_b.png").
std::string MapFileStem(const std::string& image_name);

}  // namespace fmv3d::mvs
