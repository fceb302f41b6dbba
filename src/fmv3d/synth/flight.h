// Flight paths for synthetic vision: camera poses (world-to-camera) for each frame.
//   orbit  a circle of `radius` around the look-at point at `altitude` (world z), looking at it.
//   grid   a lawn-mower pattern of nadir views at `altitude`: parallel strips ~65% side overlap,
//          alternating direction, camera x across track. With `grid_overlap` (forward, side fractions of the
//          footprint on the ground at the look-at height), the frames are laid out at exactly those overlaps
//          in as many strips as make the covered area closest to square, centred on the look-at point
//          (`radius` is then unused).
//   pass   a straight oblique pass at `altitude` beside the target, looking at it at ~45° depression.
//   oblique  a straight pass `radius` south of the target at a low `altitude`, looking north 12° below the
//          horizontal: near ground to a far horizon in every frame, as an oblique video sees a landscape.
// Each frame gets gimbal-like attitude jitter (smooth wander plus a little shake) and position jitter,
// drawn from `seed` only, so the same seed gives the same flight.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/synth/scene.h"

namespace fmv3d::synth {

enum class FlightPath { kOrbit, kGrid, kPass, kOblique };
// The spelling of the command line and truth/truth.json: "orbit", "grid", "pass", "oblique".
const char* FlightPathName(FlightPath path);
// Throws fmv3d::Error naming the accepted spellings.
FlightPath ParseFlightPath(const std::string& name);

struct FlightOptions {
  FlightPath path = FlightPath::kOrbit;
  int frames = 48;
  std::optional<double> altitude;                         // metres (world z); default per scene
  std::optional<double> radius;                           // orbit radius / grid half-size / pass stand-off, metres
  std::optional<Eigen::Vector3d> look_at;                 // default: the scene's target
  std::optional<std::pair<double, double>> grid_overlap;  // grid: (forward, side), each in [0, 0.95]
  // orbit: the altitude swings by ± this (metres) twice around the circle. Cameras at one height all looking at
  // one centre leave the principal point's row against a common tilt nearly undetermined; heights that differ
  // determine it.
  double altitude_swing = 0;
  double jitter_deg = 0.4;       // attitude jitter (1 sigma), degrees
  double position_jitter = 0.3;  // metres (1 sigma) at >= 100 m from the target, less when closer
  uint64_t seed = 1;
  void Check() const;
};

// Resolved defaults for a scene (what the flight will actually use).
struct FlightGeometry {
  double altitude = 0, radius = 0;
  Eigen::Vector3d look_at = Eigen::Vector3d::Zero();
};
FlightGeometry ResolveFlight(const Scene& scene, const core::Camera& camera, const FlightOptions& options);

std::vector<core::Pose> MakeFlight(const Scene& scene, const core::Camera& camera, const FlightOptions& options);

}  // namespace fmv3d::synth
