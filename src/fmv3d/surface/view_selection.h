// Texturing, step 1: which photograph colours each face (after Waechter, Moehrle & Goesele, "Let there be
// color!", 2014, simplified).
//
// Candidates. The mesh is rendered from every view with render::Renderer; its face-index map says which faces
// the view really sees (a depth test against the mesh itself, so walls hide what is behind them). A face is a
// candidate of a view when the view sees it (pixels in the map, or — for faces smaller than a pixel — its
// centroid passes the depth test), it faces the camera at less than `max_angle_deg`, and it lies inside the
// image. Its quality is its projected area in pixels (high resolution and frontal views score high),
// reduced by the share of it that is hidden; its colour is the mean of its pixels.
//
// Photo-consistency. A view whose colour of a face disagrees with the other views is not showing that
// surface: a car, a person or an unmodelled occluder was in front of it. Per face (colours averaged over the
// face and its neighbours, so a comparison covers a small patch, not one noisy pixel) the consensus is the
// per-channel median of the candidates; candidates farther than `consistency_threshold` DN (or 3 median
// absolute deviations, whichever is larger) from it are dropped when at least three views see the face.
//
// Labelling. Each face starts with its best consistent candidate; then iterated label voting (a few sweeps
// of iterated conditional modes on a Potts model): a face takes the view maximising
//   quality / best quality of the face  +  smoothness × (number of edge neighbours already on that view),
// so neighbouring faces share a view and seams are few, without giving up much resolution.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fmv3d/surface/frame_window.h"

namespace fmv3d::surface {

// A registered photograph: its camera, world-to-camera pose and pixels (CV_8UC3 BGR, the camera's size; empty
// when a FrameWindow gives them on demand).
struct TextureView {
  uint32_t image_id = 0;
  std::string name;
  core::Camera camera;
  core::Pose pose;
  cv::Mat image;
};

struct ViewSelectionOptions {
  double max_angle_deg = 80;          // views more oblique than this to a face are not used for it
  double consistency_threshold = 30;  // DN (0..255): colour distance from the consensus tolerated
  double smoothness = 0.6;            // weight of each agreeing neighbour in label voting
  int smoothing_iterations = 8;
  double visibility_scale = 1.0;  // render the visibility maps at this fraction of the image size
  // Per face, only the best this many candidate views (by projected area × visible share) are kept: bounds the
  // memory on long videos (a 61-view, 7.7 M-face mesh held 27 per face). The consistency check then runs over
  // those views.
  int max_candidates_per_face = 12;
  void Check() const;
};

// Edge-adjacent faces (-1 where an edge has no or more than one other face), three per face.
std::vector<Eigen::Vector3i> FaceAdjacency(const std::vector<Eigen::Vector3i>& triangles);

struct ViewSelectionStats {
  size_t faces = 0, views = 0, candidates = 0;
  double mean_candidates_per_face = 0;
  size_t inconsistent_candidates = 0;  // candidates the photo-consistency check rejected
  size_t labelled_faces = 0;
  double labelled_share = 0;
  std::vector<size_t> smoothing_changes;  // labels changed per smoothing iteration
  double seconds_visibility = 0, seconds = 0;
};

struct ViewSelection {
  std::vector<int> labels;  // per face: index into the views, -1 when no view sees it
  ViewSelectionStats stats;
};

// `frames` gives views[i]'s pixels (one pass over all of them).
ViewSelection SelectViews(const ColoredMesh& mesh, const std::vector<Eigen::Vector3i>& adjacency,
                          const std::vector<TextureView>& views, FrameWindow& frames,
                          const ViewSelectionOptions& options);

}  // namespace fmv3d::surface
