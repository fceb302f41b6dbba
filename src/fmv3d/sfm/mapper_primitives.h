// Primitives the incremental mapper composes: edits of a growing Reconstruction that keep images' point3d_ids
// and points' tracks consistent, the 2D–3D correspondences an image offers, and point filtering. Each is a plain
// function on the model (no mapper state), so each can be tested alone.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <set>
#include <utility>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/sfm/correspondence_graph.h"

namespace fmv3d::sfm {

// The 3D point an observation belongs to; kNoPoint3D when its image is not registered or it is untriangulated.
int64_t PointOf(const core::Reconstruction& rec, const core::TrackElement& el);
bool PointHasImage(const core::Reconstruction& rec, uint64_t point_id, uint32_t image_id);
// Adds (image_id, kp) to the point's track unless that keypoint already belongs to a point.
void AddObservation(core::Reconstruction* rec, uint64_t point_id, uint32_t image_id, uint32_t kp);
// Removes a point and frees the keypoints of its track (no-op for an unknown id).
void DeletePoint(core::Reconstruction* rec, uint64_t point_id);
// Removes image_id's observations from every point, deleting points left with fewer than two.
void DetachImage(core::Reconstruction* rec, uint32_t image_id);
// The (at most k) registered images sharing the most points with image_id, most first (ties: lower id first).
std::vector<uint32_t> ImagesSharingMostPoints(const core::Reconstruction& rec, uint32_t image_id, int k);

// 2D–3D correspondences of an image (registered or not) with the model: through the correspondence graph, each
// keypoint matched to a keypoint that belongs to a 3D point (each point once per keypoint).
struct Correspondences2D3D {
  std::vector<Eigen::Vector2d> points2d;  // pixels
  std::vector<Eigen::Vector3d> points3d;
  std::vector<std::pair<uint32_t, uint64_t>> keypoint_point;  // (keypoint index, point id) per correspondence
};
Correspondences2D3D FindCorrespondences2D3D(const core::Reconstruction& rec, const CorrespondenceGraph& graph,
                                            uint32_t image_id, const std::vector<Eigen::Vector2d>& keypoints);

// How many keypoints of an image see a triangulated point, and (score) how well spread they are: the occupied
// cells of 2x2, 4x4 and 8x8 grids over the image, weighted 2, 4, 8 (COLMAP's visibility pyramid).
int CountVisiblePoints(const core::Reconstruction& rec, const CorrespondenceGraph& graph, uint32_t image_id,
                       const std::vector<Eigen::Vector2d>& keypoints, int width, int height, double* score);

struct PointFilterOptions {
  double max_error_px = 4;     // observations reprojecting farther are removed
  double min_angle_deg = 1.5;  // points whose widest ray pair is narrower are deleted
};
// Removes bad observations and deletes points left with < 2 observations or too little parallax. subset:
// only these points (nullptr: all). Returns the number of points deleted.
int FilterPoints(core::Reconstruction* rec, const std::set<uint64_t>* subset, const PointFilterOptions& options);

}  // namespace fmv3d::sfm
