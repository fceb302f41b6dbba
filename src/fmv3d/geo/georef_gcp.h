// Georeference from ground control points (docs/manual-inputs.md; WS/manual/gcp_list.txt or `georef --gcp FILE`).
// GCPs outrank telemetry: when they are given, `fmv3d georef` uses them alone, and none of the frames needs
// telemetry.
//   1. Each GCP clicked in ≥ 2 registered frames is triangulated with the sparse cameras (DLT on the undistorted
//      rays, then Gauss–Newton on the normalised reprojection error).
//   2. Its coordinates (the file's CRS) go to WGS84 through GDAL/PROJ, then to a local East-North-Up frame at the
//      origin (the GCPs' centroid unless given).
//   3. The similarity sparse → ENU is the least-squares (Umeyama) fit of the triangulated control points (not the
//      check points) to their coordinates: ≥ 3 control points, not collinear.
//   4. Each point's residual |S·X_triangulated − X_enu| in metres: for control points the fit's own residual, for
//      check points (left out of the fit) the independent accuracy.
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
  Eigen::Vector3d residual_enu = Eigen::Vector3d::Zero();  // S·triangulated − enu (control / check)
  double reprojection_px = 0;  // RMS over its registered observations of the triangulated point
  bool triangulated_ok() const { return status == GcpStatus::kControl || status == GcpStatus::kCheck; }
};

struct GcpGeoref {
  GeoPoint origin;
  bool origin_given = false;
  core::Sim3 sim;  // sparse → ENU
  std::string crs, crs_name, vertical_datum;
  std::vector<GcpResult> points;
  int control_used = 0, check_used = 0;
  double control_rms_m = 0, check_rms_m = 0;  // 3D RMS of the residuals
  // georef.json's content: the keys every reader of a telemetry georeference uses (origin, vertical_datum,
  // similarity, utm, proj, trusted, ...), "source": "gcp" and "gcps".
  nlohmann::json ToJson() const;
};

// Steps 1–4. Throws fmv3d::Error (naming the points) with fewer than min_control_points triangulated control
// points or when they are collinear.
GcpGeoref EstimateGcpGeoref(const core::Reconstruction& model, const std::vector<GroundControlPoint>& gcps,
                            const GcpCrs& crs, const GcpGeorefOptions& options);

}  // namespace fmv3d::geo
