// Registration of frames through the operator's tie points (docs/manual-inputs.md), after the mapper and the
// relocalisation: a frame automatic matching left out registers when ≥ min_tie_points of its tie points are
// points of the model.
//   1. Each tie point's ground point: the model point one of its registered observations already belongs to (the
//      mapper triangulated it as a track), else triangulated from its registered observations (DLT + refinement;
//      reprojection within max_error_px, in front of every camera) and added to the model.
//   2. Each frame outside the model with ≥ min_tie_points such points: absolute pose (P3P RANSAC + refinement)
//      on them alone; accepted with ≥ min_tie_points inliers within max_error_px. Its tie-point observations
//      join the points' tracks.
//   3. Bundle adjustment of the whole model, intrinsics held, tie-point observations weighted `weight` times;
//      rounds repeat while frames register (a new frame can triangulate more tie points).
// Pure function on the model; the sparse stage calls it.
#pragma once

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

struct ManualRegistrationOptions {
  int min_tie_points = 6;
  double max_error_px = 4;
  double weight = 10;  // of a tie-point observation against an automatic one in bundle adjustment
  int max_rounds = 5;
  int ba_max_iterations = 50;
  void Check() const;
};

struct TieTrack {
  std::string id;
  std::vector<core::TrackElement> observations;  // image id (1-based), keypoint index in that image's keypoints
};

struct ManualRegistrationResult {
  std::vector<uint32_t> registered;              // frames registered through tie points, in order
  std::map<uint32_t, std::string> still_failed;  // frames with tie points that still do not register, and why
  int points_triangulated = 0;                   // tie points added to the model as new points
  struct TieReport {
    std::string id;
    int observations = 0, in_model = 0;  // observations, and those in registered frames
    bool in_point = false;               // its ground point is a model point
    double reprojection_px = 0;          // RMS over its registered observations after the adjustment
  };
  std::vector<TieReport> tie_points;
  nlohmann::json ToJson(const std::map<uint32_t, std::string>& names) const;
};

// `keypoints`: every image's keypoints (pixels; automatic then appended manual ones) by image id; `cameras`: the
// prior of every camera id (for a frame whose camera is not in the model yet); `manual_from`: per image the first
// appended index (the weighted observations). Deterministic.
ManualRegistrationResult RegisterWithTiePoints(core::Reconstruction* rec, const std::vector<TieTrack>& tracks,
                                               const std::map<uint32_t, std::vector<Eigen::Vector2d>>& keypoints,
                                               const std::map<uint32_t, std::string>& names,
                                               const std::map<uint32_t, uint32_t>& image_cameras,
                                               const std::map<uint32_t, core::Camera>& cameras,
                                               const std::map<uint32_t, uint32_t>& manual_from,
                                               const ManualRegistrationOptions& options);

}  // namespace fmv3d::sfm
