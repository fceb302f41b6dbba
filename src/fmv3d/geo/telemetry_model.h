// The telemetry-initialised model: the sparse model built again with the cameras where the telemetry puts them,
// for a clip whose images alone leave the shape ambiguous (a telephoto pass over flat ground is nearly affine).
// Cameras at the keyframes' telemetry positions and attitudes (the ST 0601 angle chain, else the line of sight to
// the frame centre at the slant range, rows level), the telemetry-HFOV camera, the image model's tracks with
// every point started where its middle ray meets the ground plane under the frame centres (triangulated from the
// telemetry cameras when there are none), then bundle adjustments with the positions as priors (σ prior_sigma_m
// per axis) and the optical axes as priors (σ attitude_sigma_deg), the intrinsics held: first with a plain loss
// (the telemetry's pointing error is common to a frame's points), then robust; last the frame centres at their
// slant range as priors, weighed by their own scatter about the adjusted model (a variance-component estimate).
#pragma once

#include <Eigen/Core>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef_pairs.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::geo {

struct TelemetryModelOptions {
  double prior_sigma_m = 3.0;       // positions' σ per axis
  double attitude_sigma_deg = 1.0;  // the telemetry line of sight's accuracy
};

// A camera whose focal came from the telemetry's field of view, replacing the image model's.
struct TelemetryFocal {
  uint32_t camera = 0;
  double f = 0;  // the telemetry's
  double f_image_model = 0, k1_image_model = 0, k2_image_model = 0;
};

struct TelemetryModel {
  core::Reconstruction model;  // ENU of the frame given
  size_t keyframes = 0, frames_left_out = 0;
  std::optional<double> ground_z_start;  // m, ENU
  std::vector<TelemetryFocal> focal_from_telemetry;
  double mean_reprojection_px_start = 0, reprojection_rms_px = 0;
  size_t observations_dropped = 0, frame_centre_priors = 0;
  std::vector<double> frame_centre_prior_sigma_m;  // per variance-component round
  double centre_rms_from_telemetry_m = 0;
  nlohmann::json ToJson(const TelemetryModelOptions& o) const;
};

// image_model: the image-only sparse model (its tracks and observations are reused); keyframes: its keyframes'
// telemetry pairs; frame_centres: ENU frame centre and slant range per keyframe name. Throws fmv3d::Error when
// fewer than 3 keyframes have a telemetry attitude or frame centre, or the bundle adjustment fails.
TelemetryModel BuildTelemetryModel(const io::FramesIndex& index, const core::Reconstruction& image_model,
                                   const std::vector<GeorefPair>& keyframes,
                                   const std::map<std::string, std::pair<Eigen::Vector3d, double>>& frame_centres,
                                   const LocalFrame& frame, const TelemetryModelOptions& options);

// RMS reprojection error (pixels) of a model's observations, recomputed (a points3D.txt error may be absent).
double ReprojectionRms(const core::Reconstruction& model);

}  // namespace fmv3d::geo
