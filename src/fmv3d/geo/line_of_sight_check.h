// The georeferenced model against the telemetry's own lines of sight. A keyframe's telemetry states the sensor
// position S and the frame centre F, the point where its line of sight meets the ground (or sea level, when the
// platform has no terrain model): the ground at the image centre lies on the ray S→F, whatever its height.
// The georeferenced model places that ground at G (the median of the sparse points seen near the image centre),
// so the angle at S between G and F is the product's disagreement with the telemetry. It is expected within the
// telemetry's pointing accuracy and the georeference's own stated accuracy (expected_accuracy, propagated to G);
// a model whose typical keyframe misses by more than max_chi of that is not trusted, and says why.
// The angle cannot see a ground placed too far along the ray. The frame centre lies where the line of sight meets
// the platform's terrain (or sea level when it has none): real ground lies at or above it, so the ray reaches it at
// or before the frame centre. A model ground below the frame centre's height (beyond it along the ray) by more than
// max_chi of σ_h = √(σ_geo² + (r·σ_pointing)²) is not trusted either.
// The disagreement is also stated on the ground: along the line of sight's horizontal direction (+ beyond) and
// across it, from the point of the ray at G's height.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/accuracy.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef_pairs.h"

namespace fmv3d::geo {

struct LineOfSightOptions {
  double pointing_sigma_deg = 1.0;  // the telemetry line of sight's accuracy (1σ per axis)
  double max_chi = 3.0;             // the median keyframe's angle over its σ above which the model is not trusted
  int min_points = 5;               // model points near the image centre for a keyframe to count
  void Check() const;
};

struct SightComparison {
  std::string name;
  Eigen::Vector3d sensor, frame_centre, model_ground;  // ENU
  double angle_rad = 0, sigma_rad = 0;
  double along_m = 0, across_m = 0;  // G − (the ray at G's height), horizontal: along the sight (+ beyond), across
  double below_m = 0;                // how far G lies below the frame centre's height (0 when above)
  double beyond_m = 0;               // G's range along the sight minus the frame centre's (+: beyond it)
  double height_sigma_m = 0;         // σ_h above
};

struct LineOfSightCheck {
  enum class Verdict { kAgrees, kDisagrees, kNotChecked };
  Verdict verdict = Verdict::kNotChecked;
  std::vector<SightComparison> keyframes;
  double median_angle_deg = 0, median_sigma_deg = 0, median_chi = 0;
  double median_below_m = 0, median_height_chi = 0;  // the ground below the frame centres, and over its σ_h
  double median_beyond_m = 0;
  double max_chi_used = 3.0;
  std::string datum_name;  // of the heights
  double median_along_m = 0, median_across_m = 0;
  double median_ground_height_m = 0, median_frame_centre_height_m = 0;  // in the georeference's vertical datum
  std::string Why() const;  // for people: what disagrees and by how much, or why nothing was checked
  nlohmann::json ToJson() const;
};

// model: the georeferenced sparse model (ENU of `frame`); keyframes: its pairs, heights in `datum`; accuracy: the
// georeference's stated accuracy (null: none). A frame centre's height is the stated one, else the one its slant
// range implies (FrameCentreHeightFromRange). Keyframes without either, or with fewer than min_points model points
// near the image centre, are not compared; none compared → kNotChecked.
LineOfSightCheck CheckLinesOfSight(const core::Reconstruction& model, const std::vector<GeorefPair>& keyframes,
                                   VerticalDatum datum, const LocalFrame& frame, const GeorefAccuracy* accuracy,
                                   const LineOfSightOptions& options);

}  // namespace fmv3d::geo
