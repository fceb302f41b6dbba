// The georeference's expected accuracy, from the telemetry alone: how well the similarity's translation, scale
// and rotation are known once the positions, attitudes and frame centres that georef used are weighed by their
// own scatter and effective sample counts. The model's own shape error is not in it (the sparse/dense reports
// measure that); what it predicts is the absolute error a surveyor would find: at 45 packets of 3 m GPS and 1°
// attitude, a 0.15° tilt is 0.13 m of height 50 m from the centre, whatever the reconstruction's quality.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::geo {

struct GeorefAccuracy {
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();         // ENU point the covariances refer to
  Eigen::Matrix3d position_cov = Eigen::Matrix3d::Zero();  // m², of the georeferenced model at the pivot
  Eigen::Matrix3d rotation_cov = Eigen::Matrix3d::Zero();  // rad², a small ENU rotation about the pivot
  double scale_sigma_rel = 0;                              // σ of the scale, relative
  bool rotation_known = true;     // false: a rotation the measurements leave free (roll about a straight track)
  std::vector<std::string> from;  // the measurements weighed

  // 1σ height error of the georeferenced point at ENU offset d from the pivot (translation, tilt, scale).
  // Requires rotation_known.
  double HeightSigma(const Eigen::Vector3d& d) const;
  nlohmann::json ToJson() const;
  // nullopt when j is not such a block (an older georef.json).
  static std::optional<GeorefAccuracy> FromJson(const nlohmann::json& j);
};

// Information (inverse covariance, rad⁻²) about a small rotation of points about their centroid when each is
// measured with σ per axis (effective: already widened for correlated samples).
Eigen::Matrix3d RotationInformation(const std::vector<Eigen::Vector3d>& points, double sigma);

}  // namespace fmv3d::geo
