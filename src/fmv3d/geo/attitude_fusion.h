// Attitude fusion: the telemetry's camera attitudes (the full ST 0601 angle chain) as a second measurement of the
// similarity's rotation. Each attitude paired with the model camera's rotation gives a model-to-ENU rotation;
// their chordal mean, with the scatter about it as its noise (fewer effective samples when neighbours' residuals
// correlate), is fused with the positions' rotation by information — only when the two agree within their
// uncertainties (χ², 3 dof, 99.9%). Scale and translation are then refitted to the positions for that rotation.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/geo/georef_pairs.h"

namespace fmv3d::geo {

struct AttitudeFusion {
  bool evaluated = false;  // at least 3 inlier pairs carry an attitude
  bool used = false;       // agreed, and the rotation was fused
  core::Sim3 sim;          // the input similarity, with the fused rotation when used
  size_t frames = 0;
  double autocorrelation = 0, effective_samples = 0;
  double sigma_rad = 0;         // scatter per axis about the mean
  double disagreement_rad = 0;  // the attitudes' rotation against the positions'
  double chi2 = 0;
  double correction_rad = 0;               // when used: how far the rotation turned
  std::vector<Eigen::Matrix3d> rotations;  // when used: the model-to-ENU rotations, for the joint refinement
  // σ per axis widened for correlated samples: σ·√(n / n_eff) (1 when not evaluated).
  double EffectiveSigma() const;
  nlohmann::json ToJson() const;
};

// pairs/src/dst/inliers: the similarity fit's pairs (model centres, ENU positions) and its inlier mask; sigma: the
// positions' residual σ per axis.
AttitudeFusion FuseAttitude(const core::Sim3& sim, const std::vector<GeorefPair>& pairs,
                            const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                            const std::vector<char>& inliers, double sigma);

Eigen::Vector3d LogRotation(const Eigen::Matrix3d& R);  // axis·angle

}  // namespace fmv3d::geo
