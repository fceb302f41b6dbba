// The reconstructed camera trajectory of one video as a function of time, from its registered keyframes: lets
// georef pair every telemetry packet (30 per second in FMV) with the model's camera position at that packet's
// time, not only the few keyframes' — the positions' noise then averages over ~10-30x more samples.
//
// Centres: cubic Lagrange interpolation through the 4 keyframes around t (2 on each side where they exist;
// exact for a cubic path, error ~ h⁴·|x''''| for knot spacing h — millimetres on an orbit sampled every 15°).
// Rotations: spherical linear interpolation between the two keyframes around t. Only inside the registered
// span, and never across a gap (two consecutive keyframes further apart than max_gap): a frame lost to SfM
// must not be bridged by a curve that may miss the real path.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <vector>

namespace fmv3d::geo {

struct TrajectoryKnot {
  double time = 0;                                               // seconds
  Eigen::Vector3d centre;                                        // camera centre
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // world-to-camera
};

class CameraTrajectory {
 public:
  // Knots in any order (sorted here; of equal times the first is kept). max_gap ≤ 0: 2.5 × the median spacing
  // of consecutive knots. Throws fmv3d::Error with fewer than 2 distinct times.
  explicit CameraTrajectory(std::vector<TrajectoryKnot> knots, double max_gap = 0);

  // The pose at time t; nullopt outside [first, last] knot time or inside a gap.
  std::optional<TrajectoryKnot> At(double t) const;

  double max_gap() const { return max_gap_; }
  double begin_time() const { return knots_.front().time; }
  double end_time() const { return knots_.back().time; }
  size_t size() const { return knots_.size(); }

 private:
  std::vector<TrajectoryKnot> knots_;
  double max_gap_ = 0;
};

}  // namespace fmv3d::geo
