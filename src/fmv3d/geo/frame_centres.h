// Frame centres as a second measurement of where the sensor was. A packet that states the frame centre F (the
// ground point on the line of sight) and the slant range r to it places the sensor at F − r·d, d the line of
// sight's direction in ENU. Georef takes d from the model's own camera rotated by the fitted similarity — not
// from the telemetry's attitude, whose error times r would dominate — so this "line-of-sight centre" carries
// the frame centre's error plus r times the fit's rotation error, independent of the GPS position's noise.
//
// How much it is worth depends on the sensor: a frame centre computed by the platform from its own GPS and
// attitude repeats their errors (aphill's EG0104 stream, ~20 m here); a rangefinder with a precise gimbal, or
// `fmv3d synth --klv` (frame centre and range from the true pose, i.e. a perfect sensor) gives centimetres. So
// nothing is assumed: the line-of-sight centres get their own scale and translation fit (rotation held at the
// positions' and attitudes'), their own robust σ and effective sample count, and are fused with the positions'
// fit by information only when the two fits agree within their uncertainties (χ², 4 dof, 99.9%).
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <utility>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/geometry/similarity.h"

namespace fmv3d::geo {

// The frame centres' fit agrees with the positions' when χ² ≤ this (4 dof, 99.9%).
constexpr double kFrameCentreAgreementChi2 = 18.47;

// One packet's (or keyframe's) line of sight: the model camera and the telemetry's frame centre and range.
struct LineOfSight {
  Eigen::Vector3d model_centre;  // model camera centre (sparse coordinates)
  Eigen::Vector3d model_axis;    // model optical axis, unit (sparse coordinates)
  double slant_range = 0;        // metres
  Eigen::Vector3d frame_centre;  // ENU metres
  int track = -1;                // consecutive entries of one track are correlated in time
};

using geometry::ScaleShift;

struct FrameCentreFusion {
  enum class Outcome {
    kUsed,
    kTooFew,            // fewer than 3 lines of sight
    kUndetermined,      // they do not determine a scale and translation
    kInconsistent,      // fewer than 3 agree with each other
    kDisagree,          // with the positions, beyond their uncertainties
    kNonPositiveScale,  // the fusion's scale
  };
  bool used = false;
  Outcome outcome = Outcome::kTooFew;
  size_t observations = 0, inliers = 0;
  std::vector<char> inlier_mask;  // per line of sight
  double sigma_m = 0;             // per axis, of the line-of-sight centres about their own fit
  double autocorrelation = 0, effective_samples = 0;
  double chi2 = 0;          // disagreement with the positions' fit
  ScaleShift fused;         // when used
  std::string Why() const;  // why not used, for people
  nlohmann::json ToJson() const;
};

// positions: the positions' fit (s, t under R), with its covariance already scaled by σ² and the effective
// sample count. min_threshold: floor of the inlier bound, metres. systematic: σ per ENU axis of an error common
// to every frame centre (the fields' encoding resolution), added to the translation's covariance.
// vertical_offset_prior: when not empty, every frame centre's height carries the same unknown offset u (all
// decode to one 2-byte step: flat ground), with these (u, weight) nodes as its prior. The fusion is then a
// posterior over u — the positions weigh where in the step the truth lies, and cannot pull it outside — instead of
// a Gaussian floor, which lets precise-looking positions drag the height past the step's edge.
FrameCentreFusion FuseFrameCentres(const Eigen::Matrix3d& R, const ScaleShift& positions,
                                   const std::vector<LineOfSight>& sights, double min_threshold,
                                   const Eigen::Vector3d& systematic = Eigen::Vector3d::Zero(),
                                   const std::vector<std::pair<double, double>>& vertical_offset_prior = {});

// The similarity refined on every measurement at once (Ceres, from `start`): positions src → dst, lines of
// sight (sensor position F − r·R·a, i.e. the frame centre F ≈ s·R·c + t + r·R·a, which also fixes the rotation
// wherever the frame centres spread), and telemetry attitudes (model-to-ENU rotations, compared with R). Each
// σ is the effective one per axis (already discounted for correlated samples); a set may be empty. A weak
// prior (5°) keeps a rotation no measurement determines (the roll about a straight track) where it started.
struct JointMeasurements {
  std::vector<Eigen::Vector3d> src, dst;
  double position_sigma = 1;
  std::vector<LineOfSight> sights;
  double sight_sigma = 1;
  std::vector<Eigen::Matrix3d> attitudes;
  double attitude_sigma_rad = 1;
};
core::Sim3 RefineSimilarity(const core::Sim3& start, const JointMeasurements& m);

// The lines of sight's own noise: their scatter about a similarity fitted to them alone (rotation free too,
// from `start`), so that the rotation error of another fit does not count as their noise — under the
// positions' rotation, precise frame centres 17 m apart show 0.1° of it as a smooth 3 cm pattern, which also
// cuts their effective count, and would then be weighed far below their worth. σ per axis (dof-corrected),
// lag-1 autocorrelation along the track, and the σ widened for it (σ·√(n / n_eff)).
struct SightScatter {
  double sigma = 0, autocorrelation = 0, effective_samples = 0, sigma_effective = 0;
};
SightScatter OwnScatter(const core::Sim3& start, const std::vector<LineOfSight>& sights, double sigma_start);

}  // namespace fmv3d::geo
