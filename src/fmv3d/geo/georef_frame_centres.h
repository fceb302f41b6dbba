// Frame-centre fusion inside georef: the keyframes' frame centres at their slant range (geo/frame_centres.h) as a
// second measurement of the sensor positions, fused into the similarity's scale and translation when they agree
// with the GPS; the rotation refined on positions, lines of sight and attitudes together when that keeps them in
// agreement. Handles the frame centre's height: its datum (converted by the geoid undulation the packets state)
// and its 2-byte ST 0601 encoding (0.30 m steps: a common offset over flat ground, a floor over relief).
#pragma once

#include <Eigen/Core>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/geo/attitude_fusion.h"
#include "fmv3d/geo/frame_centres.h"
#include "fmv3d/geo/georef_pairs.h"

namespace fmv3d::geo {

// The fit the frame centres are fused into: the similarity, its pairs' model centres src and ENU positions dst,
// the inlier mask and the positions' σ per axis.
struct PositionFit {
  core::Sim3 sim;
  std::vector<Eigen::Vector3d> src, dst;
  std::vector<char> inliers;
  double sigma = 0;
};

enum class ElevationEncoding {
  kExact,        // not on the 2-byte grid: no quantisation error
  kOneCode,      // every frame centre decodes to one 2-byte code: a common offset, a posterior over it
  kSeveralCodes  // a Gaussian floor of the step's σ over √(distinct codes)
};

struct GeorefFrameCentres {
  bool attempted = false;                   // GeorefOptions::use_frame_centres
  core::Sim3 sim;                           // the input similarity, refined when the frame centres were used
  size_t sights = 0;                        // keyframes with a frame centre, its height and a slant range
  std::optional<FrameCentreFusion> fusion;  // when the fusion ran
  size_t elevation_steps = 0;
  ElevationEncoding encoding = ElevationEncoding::kExact;
  bool both_datums = false;    // the MSL and HAE codes' common interval narrowed the step
  double offset_prior_sd = 0;  // m
  std::optional<double> undulation;
  double undulation_sigma = 0;
  struct Turn {
    double deg = 0, chi2 = 0;
    bool applied = false;
  };
  std::optional<Turn> turn;  // the joint refinement's rotation change
  // When used: what the expected accuracy weighs.
  std::vector<Eigen::Vector3d> points;  // the inlier frame centres (ENU)
  double sigma = 0;                     // their effective σ per axis
  // Every keyframe's frame centre (ENU) and slant range, by name, for the telemetry-initialised model.
  std::map<std::string, std::pair<Eigen::Vector3d, double>> by_name;

  bool used() const { return fusion && fusion->used; }
  bool disagree() const { return fusion && fusion->outcome == FrameCentreFusion::Outcome::kDisagree; }
  std::optional<double> chi2() const { return fusion ? std::optional<double>(fusion->chi2) : std::nullopt; }
  double TranslationError() const;  // m, 3D, of the fused translation (when used)
  nlohmann::json ToJson() const;
};

// fit: the positions' similarity (after the roll and the attitudes); attitude: what the attitude fusion found.
GeorefFrameCentres FuseGeorefFrameCentres(const PositionFit& fit, const PairedTelemetry& pairs,
                                          const AttitudeFusion& attitude, const LocalFrame& frame,
                                          double min_inlier_threshold);

}  // namespace fmv3d::geo
