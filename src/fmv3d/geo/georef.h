// Geo-registration (`fmv3d georef WS`): a robust similarity from the sparse model's camera centres to the
// telemetry positions that frames.json carries per frame, expressed in a local East-North-Up frame.
//
// Inputs:  WS/sparse/ (COLMAP text model), WS/frames/frames.json (per-frame "telemetry": sensor_latitude,
//          sensor_longitude, sensor_altitude_hae or else sensor_altitude_msl), and when present
//          WS/frames/telemetry.json (every packet of each video, io/telemetry.h).
// Outputs: WS/geo/sparse_enu/   the model transformed into ENU metres at the origin (x east, y north, z up)
//          WS/geo/georef.json   {"origin": {lat, lon, alt}, "vertical_datum", "similarity": {scale, rotation
//                               (quaternion wxyz and 3x3), translation, matrix 4x4; maps sparse → ENU},
//                               "residuals": {rms, median, max, sigma per axis, per image}, "inliers",
//                               "attitude": {used, frames, scatter, disagreement}, "utm": {zone, epsg, name},
//                               "proj": {enu, utm pipelines}, "wkt_utm"}
//
// Pairs: with telemetry.json, every packet inside the registered span of its video is paired with the model's
// camera at that time (CameraTrajectory through the registered keyframes: cubic in position, slerp in rotation,
// never across a gap) — 30 packets a second instead of ~2 keyframes, so white GPS noise averages ~4x further;
// else (stills, or no track) the keyframes' own telemetry.
// Estimation: least median of squares over minimal 3-camera samples (deterministic), inliers within 3.5 robust
// sigmas, Umeyama on the inliers (refined twice). A nearly straight track leaves the roll about it free: it is
// taken from the sparse points' ground plane (level in ENU). When the telemetry states the full ST 0601 angle
// chain, the frames' attitudes are fused with the positions' rotation (information-weighted; skipped when they
// disagree beyond their uncertainties) and scale/translation refitted. With GPS noise σ per axis and N
// independent pairs, the translation is known to about σ·√(3/N) (3D) — georef.json's
// expected_translation_error_m, with N discounted by the residuals' autocorrelation along the track ("fit").
// Frame centres with slant ranges are a second measurement of the sensor positions (geo/frame_centres.h): when
// they agree with the GPS, scale and translation are fused by information ("frame_centres").
// "cameras"/"inliers"/"residuals" describe the registered keyframes.
// A model that disagrees with the flight (a telephoto clip's ambiguous shape) is built again from the telemetry
// (GeorefOptions::constrain); georef.json's "telemetry_constrained" says whether, and how well.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>

#include "fmv3d/core/pose.h"
#include "fmv3d/geo/accuracy.h"
#include "fmv3d/geo/geodesy.h"

namespace fmv3d::geo {

struct GeorefOptions {
  std::optional<GeoPoint> origin;  // default: the centroid of the telemetry positions used
  int min_cameras = 3;              // with telemetry and registered
  int max_samples = 2000;           // LMedS minimal samples
  double min_inlier_threshold = 0.05;  // metres: floor of the 3σ inlier bound (noise-free telemetry)
  uint64_t seed = 42;
  bool use_track = true;  // fit every packet of frames/telemetry.json (else the keyframes' telemetry only)
  bool use_frame_centres = true;  // fuse the frame centres at their slant range when they agree (frame_centres.h)
  // When the model's trajectory disagrees with the telemetry (fit fraction below min_fit_fraction: a telephoto
  // clip over flat ground is nearly affine, its images alone leave the shape ambiguous), the model is built
  // again from the telemetry: cameras at the keyframes' telemetry positions and attitudes (the ST 0601 angle
  // chain, else the line of sight to the frame centre at the slant range), the telemetry-HFOV focal, the image
  // model's tracks started on the ground plane, then bundle-adjusted with the positions as priors (σ =
  // prior_sigma_m per axis) and the intrinsics held. Kept when it fits the telemetry better (kAlways: kept): WS/sparse is
  // replaced (the image-only model goes to WS/geo/sparse_image_only/), so the later stages use it.
  // kAuto also rebuilds when the frame centres disagree with the image model, and on a nearly straight track whose
  // frame centres agree (they fix the bend about the track that nothing else sees); kept when its frame centres
  // agree and the track fits (and, for a straight track, it reprojects within 1.5× + 0.1 px of the image model);
  // when they disagreed with the image model, also when the rebuild lowers their χ² against the positions by more
  // than the agreement threshold (frame_centres.h), reprojects within that bound and fits the track.
  // georef.json's telemetry_constrained.trigger says which.
  enum class Constrain { kAuto, kAlways, kNever };
  Constrain constrain = Constrain::kAuto;
  double min_fit_fraction = 0.8;
  double prior_sigma_m = 3.0;
  double attitude_sigma_deg = 1.0;  // the telemetry line of sight's accuracy (priors on the optical axes)
  void Check() const;
};

// The georeference that later stages read.
struct Georef {
  GeoPoint origin;
  std::string vertical_datum;  // "WGS84 ellipsoid" or "MSL"
  core::Sim3 sparse_to_enu;
  UtmZone utm;
  bool consistent_with_telemetry = true;  // false: the model's trajectory disagrees with the telemetry
  std::optional<GeorefAccuracy> accuracy;  // expected accuracy from the telemetry (older files: none)
};
// Reads WS/geo/georef.json; throws fmv3d::Error ("WS: no geo/georef.json — run `fmv3d georef` first").
Georef ReadGeoref(const std::filesystem::path& workspace);

// Robust similarity src → dst (see above), with the inlier mask and the per-axis residual sigma. A collinear
// src is fitted along its line (the roll about it is left for the caller to fix); throws fmv3d::Error with
// fewer than 3 pairs or when no sample gives a similarity.
core::Sim3 RobustSimilarity(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                            const GeorefOptions& options, std::vector<char>* inliers, double* sigma);

// Runs the stage; returns georef.json's content. Throws fmv3d::Error on missing inputs, too few frames with
// telemetry, or degenerate (collinear) camera centres.
nlohmann::json RunGeorefStage(const std::filesystem::path& workspace, const GeorefOptions& options = {});

}  // namespace fmv3d::geo
