// Mesh pieces that the cameras see through.
//
// Every dense point was seen by the cameras of its visibility list, so the segment from each of them to the point
// crosses empty space. A piece of the mesh lying across such segments is not there: Poisson fitted it to a cluster
// of outlier points floating over ground that the cameras measured behind it. Each piece other than the largest is
// drawn into every camera (its vertices, at `footprint_scale` of the image size, nearest piece per cell); each
// (point, camera) pair of the cloud whose point lands in a piece's footprint counts as
//   - through the piece: the point lies beyond the piece's depth there by more than `margin` (relative);
//   - on the piece: within `margin` of it (the piece's own points).
// A piece whose through-count exceeds `max_through_share` of both counts together, and `min_through_pairs`, is
// dropped (a handful of pairs at a small piece's rim is silhouette noise, not evidence). A real surface
// (a roof, a far building, a separate terrain patch) hides what is behind it: no camera sees a point through it,
// and what is left is noise at its silhouette (the footprint is eroded by a cell): every kept piece of the nine
// `run.sh geo` flights scores 0 through-pairs but one of 43 pairs (6 through). A piece floating over measured
// ground scores the ratio of the ground's pairs behind it to its own: near a half when as many views saw both,
// 0.2 when the piece came from more views than the ground behind it (periodic texture aliased alike in four
// consecutive views of an orbit, the ground seen by two others).
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/surface/colored_mesh.h"

namespace fmv3d::surface {

struct FreeSpaceView {
  core::Camera camera;
  core::Pose pose;  // world → camera
};

struct FreeSpaceOptions {
  double footprint_scale = 0.25;  // footprint raster size as a fraction of the image size
  double margin = 0.05;           // relative depth that separates "through" from "on"
  double max_through_share = 0.1;
  double min_through_pairs = 20;
  void Check() const;
};

struct FreeSpaceStats {
  size_t pieces = 0;   // connected pieces of the mesh
  size_t tested = 0;   // pieces other than the largest
  size_t dropped = 0;  // seen through
  size_t faces_dropped = 0;
};

// Removes the pieces of `mesh` that the cloud's cameras see through (above). Needs the cloud's visibility lists;
// a point's camera missing from `views` is skipped. Pure apart from the mesh it edits.
FreeSpaceStats DropPiecesInFreeSpace(ColoredMesh* mesh, const io::OrientedPointCloud& cloud,
                                     const std::map<uint32_t, FreeSpaceView>& views,
                                     const FreeSpaceOptions& options = {});

}  // namespace fmv3d::surface
