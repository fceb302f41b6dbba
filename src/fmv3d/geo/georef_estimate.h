// The georeference of one sparse model from its telemetry pairs (geo/georef_pairs.h), in memory:
//   1. a least-median-of-squares similarity from the model's camera centres to the ENU positions
//      (geometry/similarity.h; inliers within 3.5 robust σ, refitted);
//   2. the roll about a nearly straight track from the model's ground plane (geo/roll_levelling.h);
//   3. the telemetry attitudes fused into the rotation when they agree (geo/attitude_fusion.h);
//   4. the frame centres at their slant range fused into scale and translation, and the rotation refined on every
//      measurement, when they agree (geo/georef_frame_centres.h);
//   5. the expected accuracy (geo/accuracy.h) and the fit's own figures: with GPS noise σ per axis and N
//      independent pairs the translation is known to about σ·√(3/N) (3D), N discounted by the residuals'
//      autocorrelation along the track.
// A model whose trajectory has the telemetry's shape fits nearly every packet (synthetic flights: 98%); when a
// large part does not fit (fit_fraction < min_fit_fraction), the reconstruction's shape is wrong (too little
// parallax, a telephoto pair's ambiguous pose) and every product placed by this similarity inherits it.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/geo/accuracy.h"
#include "fmv3d/geo/attitude_fusion.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef_frame_centres.h"
#include "fmv3d/geo/georef_pairs.h"
#include "fmv3d/geo/roll_levelling.h"
#include "fmv3d/geometry/similarity.h"

namespace fmv3d::geo {

struct GeorefOptions {
  std::optional<GeoPoint> origin;      // default: the centroid of the telemetry positions used
  int min_cameras = 3;                 // with telemetry and registered
  int max_samples = 2000;              // LMedS minimal samples
  double min_inlier_threshold = 0.05;  // metres: floor of the 3σ inlier bound (noise-free telemetry)
  uint64_t seed = 42;
  bool use_track = true;          // fit every packet of frames/telemetry.json (else the keyframes' telemetry only)
  bool use_frame_centres = true;  // fuse the frame centres at their slant range when they agree (frame_centres.h)
  // When the image model disagrees with the telemetry it is built again from it (geo/telemetry_model.h) and kept
  // when that mends what was wrong (geo/georef.h); kAlways keeps the rebuild, kNever never builds one.
  enum class Constrain { kAuto, kAlways, kNever };
  Constrain constrain = Constrain::kAuto;
  double min_fit_fraction = 0.8;
  double prior_sigma_m = 3.0;
  double attitude_sigma_deg = 1.0;  // the telemetry line of sight's accuracy (priors on the optical axes)
  // Ground control points (geo/georef_gcp.h) outrank telemetry: gcp_file, else WS/manual/gcp_list.txt when it
  // exists (unless use_gcps is false).
  std::optional<std::filesystem::path> gcp_file;
  bool use_gcps = true;
  bool gcp_adjust = true;  // the bundle adjustment with GCP constraints after their similarity (georef_gcp.h)
  void Check() const;
};

struct KeyframeResidual {
  std::string name;
  Eigen::Vector3d enu_error = Eigen::Vector3d::Zero();  // georeferenced centre − telemetry position
  bool inlier = false;
};

struct GeorefSolution {
  GeoPoint origin;
  bool origin_given = false;  // GeorefOptions::origin, else the telemetry centroid
  VerticalDatum datum = VerticalDatum::kEllipsoid;
  core::Sim3 sim;                 // sparse → ENU
  geometry::SimilarityLMedS fit;  // the positions' robust fit (its inliers and σ)
  RollSource roll_source = RollSource::kCameraPositions;
  AttitudeFusion attitude;
  GeorefFrameCentres frame_centres;
  std::vector<KeyframeResidual> keyframes;  // the registered keyframes (the cameras later stages use)
  // The fit: its pairs (track packets or keyframes) and inliers, their residuals' lag-1 autocorrelation and the
  // effective sample count n·(1−ρ)/(1+ρ).
  bool use_track = false, track_file = false;
  size_t track_samples = 0, track_spanned = 0;
  size_t fit_pairs = 0, fit_inliers = 0;
  double autocorrelation = 0, effective_samples = 1;
  double expected_translation_error_m = 0;
  GeorefAccuracy accuracy;
  double fit_fraction = 0;
  bool consistent_with_telemetry() const;  // fit_fraction ≥ min_fit_fraction
  double min_fit_fraction = 0.8;
  double inlier_bound_m = 0;  // max(min_inlier_threshold, 3.5σ)
  // georef.json's content (without "telemetry_constrained", which the stage adds).
  nlohmann::json ToJson() const;
};

// georef.json's "similarity": scale, rotation (wxyz and 3x3), translation, 4x4 matrix (sparse → ENU).
nlohmann::json GeorefSimilarityJson(const core::Sim3& sim);
// The local frame's description in georef.json ("utm", "proj", "to_wgs84", "wkt_utm"), which later stages read.
void AddLocalFrameJson(const LocalFrame& frame, nlohmann::json* georef);

// Steps 1–5 above. model_points: the sparse model's points (for the ground plane). Throws fmv3d::Error on
// degenerate camera positions or a straight track without enough points to find the ground.
GeorefSolution EstimateGeoref(const PairedTelemetry& pairs, const std::vector<Eigen::Vector3d>& model_points,
                              const GeoPoint& origin, bool origin_given, const GeorefOptions& options);

}  // namespace fmv3d::geo
