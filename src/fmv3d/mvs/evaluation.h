// Accuracy and completeness of a dense cloud against a synthetic scene (`fmv3d synth` output):
//  - the sparse model is aligned to the true cameras by a similarity (sfm::EvaluateSparse, images by name)
//    and the cloud is carried along;
//  - accuracy: distance of every fused point to the true mesh (median, 90th percentile), also as a fraction
//    of the characteristic length (the tallest building's height);
//  - completeness: the true surface is sampled uniformly; a sample counts when at least `min_cameras` true
//    cameras see it (depth test against the rasterised truth depth maps), and it is complete when a fused
//    point lies within completeness_fraction · characteristic length of it.
#pragma once

#include <Eigen/Geometry>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::mvs {

struct DenseEvaluationOptions {
  double completeness_fraction = 0.01;   // of the characteristic length
  int min_cameras = 2;                   // true cameras that must see a surface sample
  size_t max_surface_samples = 1500000;  // sample spacing grows on large scenes to stay below this
  double min_spacing_fraction = 0.0025;  // finest sample spacing, of the characteristic length
  size_t max_accuracy_points = 3000000;  // evenly thinned beyond this
  int render_max_size = 800;             // truth depth maps for the visibility test, longer side
  // Completeness counts only surface inside this box (e.g. truth.json "bounds": the modelled area, not the
  // coarse backdrop ring synth adds for the horizon); empty box = everywhere.
  Eigen::AlignedBox3d region;
  bool keep_missed = false;  // fill DenseEvaluation::missed_samples (to see where completeness is lost)
  void Check() const;
};

// Figures of one part of the scene, to see where accuracy and completeness are lost: points by the surface
// they lie nearest (horizontal = ground and flat roofs, |n_z| >= 0.8; else facades and pitched roofs; inside or
// outside the evaluation region), surface samples by orientation and by how many true cameras see them.
struct DenseBreakdown {
  std::string name;
  size_t points = 0;
  double median_error = 0, p90_error = 0;
  size_t seen_samples = 0, complete_samples = 0;
};

struct DenseEvaluation {
  size_t points = 0;
  double characteristic_length = 0;
  double median_error = 0, p90_error = 0, mean_error = 0, rms_error = 0;  // truth units
  double within_1_percent = 0;                                            // share of points within 1% of the length
  // The same for the points nearest the modelled region's surface (synth's backdrop ring left out: a coarse,
  // blurred horizon filler); the figures above when there is no region.
  double region_median_error = 0, region_p90_error = 0, region_rms_error = 0;
  size_t region_points = 0;
  size_t surface_samples = 0, seen_samples = 0, complete_samples = 0;
  double completeness = 0;             // in the region
  double completeness_everywhere = 0;  // all the seen surface (the region's when it is everywhere)
  size_t seen_samples_everywhere = 0;
  double sample_spacing = 0;
  // Stated σ (truth units) against the true error, when the cloud has one: share exceeded, all points and
  // those outside the region (the far field of the synthetic scenes); -1 when there is no σ / no such point.
  double sigma_exceeded = -1, sigma_exceeded_outside = -1, median_sigma = 0;
  core::Sim3 alignment;  // model → truth
  std::vector<DenseBreakdown> breakdown;
  std::vector<Eigen::Vector3d> missed_samples;  // region samples seen by min_cameras with no point near (keep_missed)
  double median_fraction() const { return median_error / characteristic_length; }
  double p90_fraction() const { return p90_error / characteristic_length; }
  nlohmann::json ToJson() const;
};

// `cloud` is in the estimate's frame. Throws fmv3d::Error when the models share fewer than 3 images, the
// cloud is empty or the characteristic length is not positive.
DenseEvaluation EvaluateDense(const io::OrientedPointCloud& cloud, const core::Reconstruction& estimate,
                              const core::Reconstruction& truth, const io::TexturedMesh& scene,
                              double characteristic_length, const DenseEvaluationOptions& options = {});

}  // namespace fmv3d::mvs
