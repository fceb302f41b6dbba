// Scene points of a synthetic flight's ground truth and their true pixel positions in the frames that see them:
// what an operator would click as tie points or GCPs, computed exactly (tests, the console's browser test, and
// `fmv3d truth-projections`). Visibility comes from the truth tracks (synth samples surface points and keeps
// the frames where the depth test passes); pixels are re-projected with the true camera (fmv3d convention,
// pixel centres at +0.5), optionally with Gaussian noise.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::synth {

struct TruthPointOptions {
  int points = 10;
  int min_frames = 2;  // a point must be seen by at least this many frames (of the allowed ones)
  // Frames a point must be seen in (every one of them); empty: none required.
  std::vector<std::string> required_frames;
  // Frames whose observations are kept (empty: all). A point counts min_frames over these only.
  std::vector<std::string> allowed_frames;
  // Per required frame, keep points at least this far (pixels) from the image border.
  double border_px = 8;
  double noise_px = 0;      // σ of Gaussian noise per pixel coordinate
  double noise_max_px = 0;  // or: uniform noise in [−noise_max_px, noise_max_px] per coordinate ("±1 px")
  uint64_t seed = 1;
  void Check() const;
};

struct TruthPoint {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();  // world (metres; with a geo origin, its ENU frame)
  std::vector<io::ImagePoint> observations;       // true (+ noise) pixels, frames in truth order
};

// Picks points.points points spread over the scene (farthest-point sampling in 3D among the eligible ones, from
// the one seen by most frames; deterministic). Throws fmv3d::Error when fewer are eligible.
std::vector<TruthPoint> SelectTruthPoints(const core::Reconstruction& truth, const TruthPointOptions& options);

}  // namespace fmv3d::synth
