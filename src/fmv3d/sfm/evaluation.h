// Accuracy of a reconstruction against ground truth, measured the way ANCHORS.md reports COLMAP:
//  - similarity (Umeyama) alignment of our camera centres to the true ones, images matched by name (with their
//    viewing directions on a straight track: AlignmentSource);
//  - centre RMSE after alignment, as a fraction of the true cameras' extent, where the extent is the LARGEST
//    PAIRWISE DISTANCE between true camera centres (the set's diameter);
//  - median over all image pairs of the angle of R_rel_est · R_rel_trueᵀ, with R_rel = R_j R_iᵀ (gauge-free);
//  - relative focal error |f_est − f_true| / f_true per camera (matched through the first image using it), and
//    the distance between the principal points in pixels;
//  - the lens model's residual distortion at the image corners (LensResidualPx).
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"

namespace fmv3d::sfm {

// What the similarity to the truth was fitted on. Centres on a straight track (a pass, an oblique clip) fix scale
// and translation but hardly the rotation about the track: only their jitter across it does, and a rotation of a
// tenth of a degree moves far ground by metres. When the true centres' cross-track spread is under a tenth of the
// along-track one (geometry::Collinearity), each camera's viewing direction takes part as well; orbits and grids
// keep the centres-only fit, as ANCHORS.md measures COLMAP.
enum class AlignmentSource { kCentres, kCentresAndViewDirections };
inline constexpr double kCollinearTrack = 0.1;

struct SparseEvaluation {
  int num_truth_images = 0;
  int num_matched = 0;              // our images found in the truth by name
  double centre_rmse = 0;           // same units as the truth
  double extent = 0;                // max pairwise distance of the matched true centres
  double centre_rmse_fraction = 0;  // centre_rmse / extent
  double median_rotation_error_deg = 0;
  double max_centre_error_fraction = 0;
  // Worst over matched cameras, of the focal f (the vertical one, fy; fx = f·aspect) and of fx: with the aspect
  // held at 1 the estimate's single focal is compared with the truth's fy.
  double focal_relative_error = 0, focal_x_relative_error = 0;
  double principal_point_error_px = 0;  // worst over matched cameras: distance between the principal points
  double lens_residual_corner_px = 0;   // worst over matched cameras: LensResidualPx
  Eigen::Vector3d systematic_rotation_deg = Eigen::Vector3d::Zero();  // see ToJson
  core::Sim3 alignment;                                               // ours → truth
  AlignmentSource alignment_from = AlignmentSource::kCentres;
  nlohmann::json ToJson() const;
};

// Residual distortion of an estimated lens against the true one, in pixels: the largest difference, over the four
// image corners, between the distortion displacements of the two models, where a model's displacement at pixel p is
// p minus where its own pinhole (same f, s_u, u0, v0, no distortion) puts the ray p sees. Focal and principal point
// errors are not part of it (evaluated on their own above); the cameras must have the same size.
double LensResidualPx(const core::Camera& estimate, const core::Camera& truth);

// The similarity taking our centres ce (poses pe) to the true ones ct (pt), matched by index; extent in truth
// units (see AlignmentSource). Throws when the centres have no spread.
core::Sim3 AlignToTruth(const std::vector<Eigen::Vector3d>& ce, const std::vector<Eigen::Vector3d>& ct,
                        const std::vector<core::Pose>& pe, const std::vector<core::Pose>& pt, double extent,
                        AlignmentSource* from);

// Throws fmv3d::Error when fewer than 3 images can be matched by name (no alignment possible).
SparseEvaluation EvaluateSparse(const core::Reconstruction& estimate, const core::Reconstruction& truth);

// Error of a similarity found between two reconstructions (`moving` → `reference`, e.g. by `fmv3d align`)
// against the truth composed from each one's own alignment to its ground truth (same world for both):
// E = S_ref ∘ found ∘ S_mov⁻¹ should be the identity. Rotation of E, |scale − 1|, and how far E moves
// `centre` (a truth-frame point, e.g. the moving model's centroid) as a fraction of the reference's extent.
struct SimilarityError {
  double rotation_deg = 0;
  double scale = 0;
  double translation_fraction = 0;
};
SimilarityError CompareSimilarityToTruth(const core::Sim3& found, const SparseEvaluation& reference,
                                         const SparseEvaluation& moving, const Eigen::Vector3d& centre);

// Median relative-rotation error (degrees) over all pairs of corresponding poses (same order in both lists).
double MedianRelativeRotationErrorDeg(const std::vector<core::Pose>& estimate, const std::vector<core::Pose>& truth);

// Loads ground truth from a COLMAP text model folder, or from a Strecha folder of NAME.camera files
// (io::ReadStrechaCameras).
core::Reconstruction LoadTruth(const std::string& dir);

}  // namespace fmv3d::sfm
