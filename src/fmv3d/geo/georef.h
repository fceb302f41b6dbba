// Geo-registration (`fmv3d georef WS`): a robust similarity from the sparse model's camera centres to the
// telemetry positions that frames.json carries per frame, expressed in a local East-North-Up frame. Ground
// control points outrank telemetry: with WS/manual/gcp_list.txt (or GeorefOptions::gcp_file) the similarity
// comes from them instead (geo/georef_gcp.h), and no telemetry is needed.
//
// Inputs:  WS/sparse/ (COLMAP text model), WS/frames/frames.json (per-frame "telemetry": sensor_latitude,
//          sensor_longitude, sensor_altitude_hae or else sensor_altitude_msl), and when present
//          WS/frames/telemetry.json (every packet of each video, io/telemetry.h).
// Outputs: WS/geo/sparse_enu/   the model transformed into ENU metres at the origin (x east, y north, z up)
//          WS/geo/georef.json   {"origin": {lat, lon, alt}, "vertical_datum", "similarity": {scale, rotation
//                               (quaternion wxyz and 3x3), translation, matrix 4x4; maps sparse → ENU},
//                               "residuals": {rms, median, max, sigma per axis, per image}, "inliers",
//                               "attitude", "frame_centres", "fit", "expected_accuracy", "fit_fraction",
//                               "consistent_with_telemetry", "telemetry_constrained", "line_of_sight",
//                               "trusted", "utm": {zone, epsg, name}, "proj": {enu, utm pipelines}, "wkt_utm"}
//
// The pieces: the pairs (geo/georef_pairs.h), the estimate (geo/georef_estimate.h: LMedS similarity, roll from
// the ground, attitude and frame-centre fusion, expected accuracy), the telemetry-initialised model
// (geo/telemetry_model.h) and the check against the telemetry's lines of sight (geo/line_of_sight_check.h).
//
// A model that disagrees with the flight is built again from the telemetry (GeorefOptions::constrain), both are
// georeferenced in memory and compared (ChooseModel below); WS/sparse is replaced only when the rebuild is kept
// (the image-only model then goes to WS/geo/sparse_image_only/), so the later stages use it.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "fmv3d/core/pose.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/accuracy.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef_estimate.h"

namespace fmv3d::geo {

// The georeference that later stages read.
struct Georef {
  GeoPoint origin;
  std::string vertical_datum;          // as georef.json names it: "WGS84 ellipsoid", "MSL" or a GCP CRS's own
  std::optional<VerticalDatum> datum;  // the same, parsed; nullopt for a GCP CRS's own datum
  core::Sim3 sparse_to_enu;
  UtmZone utm;
  bool consistent_with_telemetry = true;  // false: the model's trajectory disagrees with the telemetry
  // false: the georeferenced model disagrees with the telemetry's lines of sight beyond the stated accuracy
  // (georef.json "trusted"; older files: true); why in untrusted_reason.
  bool trusted = true;
  std::string untrusted_reason;
  std::optional<GeorefAccuracy> accuracy;  // expected accuracy from the telemetry (older files: none)
};
// Reads WS/geo/georef.json; throws fmv3d::Error ("WS: no geo/georef.json — run `fmv3d georef` first").
Georef ReadGeoref(const core::Workspace& workspace);

// Why the image-only model is built again from the telemetry (GeorefOptions::constrain).
enum class RebuildTrigger {
  kNone,
  kForced,                         // --constrain always
  kTrackDoesNotFit,                // fit fraction below min_fit_fraction: the shape is wrong
  kFrameCentresDisagree,           // with the model placed by the positions (its lines of sight are bent)
  kStraightTrackWithFrameCentres,  // they fix the bend about the track that nothing else sees
};
const char* RebuildTriggerName(RebuildTrigger t);
RebuildTrigger WhyRebuild(const GeorefSolution& image_model, GeorefOptions::Constrain constrain);

// Whether the rebuild is kept (kAuto): it mends what was wrong —
//   kTrackDoesNotFit: more of the track fits it;
//   otherwise: its frame centres agree with it, or (kFrameCentresDisagree) their χ² against the positions drops
//   by more than the agreement band (kFrameCentreAgreementChi2) while it reprojects within 1.5× + 0.1 px of the
//   image model — and the track fits it; for kStraightTrackWithFrameCentres it must also reproject that well (or
//   a coarse HFOV is being traded for the bend).
bool RebuildMends(RebuildTrigger trigger, const GeorefSolution& image_model, const GeorefSolution& rebuilt,
                  double image_reprojection_px, double rebuilt_reprojection_px);

// Runs the stage; returns georef.json's content. Throws fmv3d::Error on missing inputs, too few frames with
// telemetry, or degenerate (collinear) camera centres.
nlohmann::json RunGeorefStage(const core::Workspace& workspace, const GeorefOptions& options = {});

}  // namespace fmv3d::geo
