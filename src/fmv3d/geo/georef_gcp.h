// Georeference from ground control points (docs/manual-inputs.md; WS/manual/gcp_list.txt or `georef --gcp FILE`).
// GCPs outrank telemetry: when they are given, `fmv3d georef` uses them alone, and none of the frames needs
// telemetry.
//   1. Each GCP clicked in ≥ 2 registered frames is triangulated with the sparse cameras (DLT on the undistorted
//      rays, then Gauss–Newton on the normalised reprojection error).
//   2. Its coordinates (the file's CRS) go to WGS84 through GDAL/PROJ, then to a local East-North-Up frame at the
//      origin (the GCPs' centroid unless given).
//   3. The similarity sparse → ENU is the least-squares (Umeyama) fit of the triangulated control points (not the
//      check points) to their coordinates, each weighted by the inverse variance of its triangulation (from the
//      Jacobians of its projections): ≥ 3 control points, not collinear. That fit then starts a Gauss–Newton of the
//      seven parameters on the clicks themselves (each control point at its coordinates, carried into the model and
//      reprojected): the maximum-likelihood datum for the model's shape, every click weighed by its own geometry.
//   4. Bundle adjustment with GCP constraints (unless options.adjust is off): the model, carried to ENU by that
//      similarity, is adjusted with the control points as extra 3D points held (softly, σ = gcp_sigma_m) at their
//      coordinates and their clicks as reprojection residuals beside every automatic observation, weighted by
//      (σ_auto / σ_click)², both measured, so that a camera's pose does not bend towards its own few noisy clicks.
//      The datum is then fitted to the clicks themselves, each weighed by its actual geometry (not by one scalar
//      per point), and cameras, points and the focal move with it, so the model's shape, not only its placement,
//      follows the GCPs (k1, k2 stay the sparse stage's). `sim` becomes the least-squares similarity of the sparse
//      model's camera centres onto the adjusted ones (for products made from sparse/).
//   5. Each point's residual |X − X_enu| in metres, X triangulated again with the final (adjusted) cameras: for
//      control points the fit's own residual, for check points (left out of the fit) the independent accuracy.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/gcp_list.h"
#include "fmv3d/geo/geodesy.h"

namespace fmv3d::geo {

struct GcpGeorefOptions {
  std::optional<GeoPoint> origin;  // default: the centroid of the GCPs (WGS84)
  int min_control_points = 3;
  bool fit_to_clicks = true;  // step 3's Gauss–Newton on the clicks (off: the precision-weighted Umeyama fit alone)
  bool adjust = true;         // step 4
  bool refine_focal = true;   // step 4 adjusts the focal too (an orbit trades it against the cameras' distance)
  double gcp_sigma_m = 0.02;  // survey accuracy of a control point's coordinates, per axis (step 4's priors)
  void Check() const;
};

enum class GcpStatus {
  kControl,          // used in the fit
  kCheck,            // a check point: triangulated, left out of the fit
  kTooFewFrames,     // fewer than 2 observations in registered frames: not triangulated
  kNotTriangulated,  // the rays do not meet in front of the cameras
};
const char* GcpStatusName(GcpStatus s);

struct GcpResult {
  std::string name;
  GcpStatus status = GcpStatus::kTooFewFrames;
  int observations = 0, registered_observations = 0;
  Eigen::Vector3d enu = Eigen::Vector3d::Zero();           // the GCP's coordinates in the local frame
  Eigen::Vector3d triangulated = Eigen::Vector3d::Zero();  // in the sparse model's frame
  Eigen::Vector3d residual_enu = Eigen::Vector3d::Zero();  // triangulated in the final ENU model − enu
  double reprojection_px = 0;  // RMS over its registered observations of the triangulated point
  double sigma_per_px = 0;     // σ of the triangulated point (model units, √trace Σ) for a 1 px click error
  bool triangulated_ok() const { return status == GcpStatus::kControl || status == GcpStatus::kCheck; }
};

// Step 4's bundle adjustment, as georef.json reports it.
struct GcpAdjustment {
  bool applied = false;
  std::string why_not;      // when not applied
  int observations = 0;     // control-point clicks in the adjustment
  double click_weight = 1;  // their weight against an automatic observation: (σ_auto / σ_click)²
  double gcp_rms_px_before = 0, gcp_rms_px_after = 0;  // RMS reprojection error of those clicks
  double rms_px_before = 0, rms_px_after = 0;          // of every observation
  double max_camera_shift_m = 0;                       // largest camera centre move against the similarity placement
  double seconds = 0;
};

struct GcpGeoref {
  GeoPoint origin;
  bool origin_given = false;
  core::Sim3 sim;                       // sparse → ENU (step 3, or fitted to step 4's result)
  bool datum_fitted_to_clicks = false;  // step 3's Gauss–Newton on the clicks lowered their error
  core::Reconstruction enu;             // the model in ENU: adjusted (step 4), else sim applied to the sparse model
  GcpAdjustment adjustment;
  std::string crs, crs_name, vertical_datum;
  std::vector<GcpResult> points;
  int control_used = 0, check_used = 0;
  double control_rms_m = 0, check_rms_m = 0;  // 3D RMS of the residuals
  // georef.json's content: the keys every reader of a telemetry georeference uses (origin, vertical_datum,
  // similarity, utm, proj, trusted, ...), "source": "gcp" and "gcps".
  nlohmann::json ToJson() const;
};

// Steps 1–5. Throws fmv3d::Error (naming the points) with fewer than min_control_points triangulated control
// points or when they are collinear.
GcpGeoref EstimateGcpGeoref(const core::Reconstruction& model, const std::vector<GroundControlPoint>& gcps,
                            const GcpCrs& crs, const GcpGeorefOptions& options);

}  // namespace fmv3d::geo
