// Incremental triangulation over the correspondence graph (COLMAP's IncrementalTriangulator in shape):
//   - create: a keypoint of a registered image and its registered, untriangulated correspondences (one per
//     image) become a point — a small RANSAC over observation pairs (a track can hold a wrong match), the DLT
//     of the inliers refined by Gauss–Newton, kept when it has two inliers and enough parallax;
//   - continue: a keypoint whose correspondence already belongs to a point joins the best-fitting such point;
//   - complete: a point gains every correspondence (breadth-first, so transitively) that reprojects well;
//   - merge: two points joined by a correspondence become one when every observation of both agrees with the
//     better-supported position.
// Every decision is by reprojection error in pixels (max_error_px); creation also needs min_angle_deg.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/sfm/correspondence_graph.h"

namespace fmv3d::sfm {

struct TriangulatorOptions {
  double max_error_px = 4;     // creation, continuation, completion and merging
  double min_angle_deg = 1.5;  // creation: the widest ray pair of the inliers
  // Creation skips tracks of two views (IsTwoViewObservation), as COLMAP's mapper does: no third image can
  // observe such a point, so it never helps a registration nor checks its match; it only ties its two images in
  // bundle adjustment, which their many longer tracks already do. (The initial pair's points are created
  // directly and keep them.)
  bool ignore_two_view_tracks = true;
};

class IncrementalTriangulator {
 public:
  // Colour of a keypoint (false when unknown); the new point takes its first observation's colour.
  using KeypointColour = std::function<bool(uint32_t image_id, uint32_t kp, Eigen::Matrix<uint8_t, 3, 1>* rgb)>;

  // rec and graph must outlive the triangulator; it only adds points and observations to rec (and deletes the
  // points it merges away). New point ids continue after the largest id in rec.
  IncrementalTriangulator(const CorrespondenceGraph& graph, core::Reconstruction* rec,
                          const TriangulatorOptions& options, KeypointColour colour = nullptr);

  void set_min_angle_deg(double deg) { options_.min_angle_deg = deg; }
  const TriangulatorOptions& options() const { return options_; }

  // Creates one point from these observations (registered images, distinct images). Returns its id, or
  // kNoPoint3D when no two observations agree.
  int64_t CreatePoint(const std::vector<core::TrackElement>& observations);
  // Continues or creates the point of one keypoint of a registered image.
  void TriangulateKeypoint(uint32_t image_id, uint32_t kp);
  // Adds well-reprojecting correspondences to the point. Returns the number of observations added.
  int CompletePoint(uint64_t point_id);
  // Merges the points that share correspondences with this one. Returns the number of points merged in.
  int MergePoint(uint64_t point_id);
  // After an image was registered: triangulate its keypoints, then complete and merge its points.
  // Returns the number of new points.
  int TriangulateImage(uint32_t image_id);
  // Over the whole model (after a bundle adjustment moved the cameras): triangulate every keypoint, complete
  // and merge every point. Returns new points + added observations + merges.
  int Retriangulate();

 private:
  const CorrespondenceGraph& graph_;
  core::Reconstruction* rec_;
  TriangulatorOptions options_;
  KeypointColour colour_;
  uint64_t next_point_id_ = 1;
};

}  // namespace fmv3d::sfm
