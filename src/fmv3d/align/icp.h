// Scaled ICP: refines a similarity X' = s·R·X + t that puts a source point set onto a target surface.
//
// The shape follows Open3D's registration pipeline: one loop (ScaledIcp) alternates
//   1. correspondences — each (subsampled) source point, moved by the current estimate, takes its nearest
//      target point from a kd-tree; pairs beyond a distance, with disagreeing normals, or in the worst
//      (1 − trim_fraction) share are dropped (trimmed ICP, Chetverikov et al. 2002: the parts of either set
//      that the other does not cover must not pull the estimate);
//   2. an update of the similarity by an estimation object (SimilarityEstimation):
//      - PointToPointEstimation: weighted Umeyama, closed form (robust to a poor start, slow near the end);
//      - PointToPlaneEstimation: Chen–Medioni point-to-tangent-plane residuals n_q·(X' − q), optionally with
//        a colour term (Park, Zhou & Koltun 2017: the target's intensity extrapolated along its tangent plane
//        by a per-point gradient) and a normal-agreement weight; unknowns rotation (angle-axis), translation
//        and log-scale, solved by Levenberg–Marquardt in Ceres with a robust loss.
//   until the update moves no point by more than `tolerance` × the source's radius (or, at the noise floor,
//   the updates stop shrinking below 1e-5 of the radius).
// Point-to-plane lets flat parts slide along themselves, which is what makes it converge in a few iterations
// where point-to-point crawls; with scale free it needs structure in more than one direction (any real scene).
//
// ICP is local: it needs a start within roughly a tenth of the scene's size and ~20° of the truth. A start
// from nothing comes from global_registration.h.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "fmv3d/align/point_index.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::align {

enum class RobustLoss { kNone, kHuber, kCauchy };
RobustLoss ParseRobustLoss(const std::string& name);  // none | huber | cauchy; throws fmv3d::Error otherwise

struct IcpOptions {
  bool estimate_scale = true;
  // Correspondences farther apart than this (target units) are dropped. 0: adaptive — unlimited in the first
  // iteration (trimming alone), then 3 robust standard deviations of the current distances, never below
  // 3 target spacings.
  double max_correspondence_distance = 0;
  // Share of the closest correspondences kept each iteration (1 = all): set it near the expected overlap.
  double trim_fraction = 0.9;
  // Pairs whose normals make a cosine below this are dropped; the others are weighted by the cosine.
  // (Unoriented normals — estimated by PCA — are compared by |cos|.) Ignored when the source has no normals.
  double min_normal_cos = 0.3;
  // Share λ of the colour term in [0, 1): cost = (1 − λ)·Σ(geometric/spacing)² + λ·Σ(intensity difference)²,
  // geometry measured in target point spacings and intensity in [0, 1]. 0 = geometry only. Needs colours
  // on both sets.
  double colour_weight = 0;
  RobustLoss loss = RobustLoss::kCauchy;
  // Robust loss scale in target spacings; 0 = 2.5 robust standard deviations of the current residuals.
  double loss_scale = 0;
  int max_iterations = 60;
  double tolerance = 1e-9;        // converged when the last update moved every point by < tolerance × radius
  int max_source_points = 60000;  // evenly spread subsample of the source used for the fit (0 = all)
  int normal_neighbours = 20;     // k for PCA normals when a set has none
  int lm_iterations = 10;         // Levenberg–Marquardt iterations per ICP iteration
  // Throws fmv3d::Error naming the bad field.
  void Check() const;
};

// The target, prepared once (kd-tree, normals, intensity gradients) and reusable for several sources.
class IcpTarget {
 public:
  // Normals are estimated (unoriented) when the cloud has none; intensity gradients are computed when
  // `with_colour` and the cloud has colours. Throws fmv3d::Error for fewer than 3 points.
  explicit IcpTarget(const io::OrientedPointCloud& cloud, int normal_neighbours = 20, bool with_colour = false);

  const std::vector<Eigen::Vector3d>& points() const { return points_; }
  const std::vector<Eigen::Vector3d>& normals() const { return normals_; }
  bool normals_oriented() const { return normals_oriented_; }
  bool has_colour() const { return !intensity_.empty(); }
  const std::vector<double>& intensity() const { return intensity_; }
  const std::vector<Eigen::Vector3d>& gradients() const { return gradients_; }  // ⊥ normal, per unit length
  const PointIndex& index() const { return index_; }
  double spacing() const { return spacing_; }  // median nearest-neighbour distance
  double radius() const { return radius_; }    // RMS distance to the centroid

 private:
  std::vector<Eigen::Vector3d> points_, normals_, gradients_;
  std::vector<double> intensity_;
  bool normals_oriented_ = false;
  PointIndex index_;
  double spacing_ = 0, radius_ = 0;
};

struct Correspondence {
  int source = 0, target = 0;
  double weight = 1;
};

// The source as the estimation sees it: points (and normals, intensities) already moved by the current
// estimate.
struct IcpSource {
  std::vector<Eigen::Vector3d> points, normals;  // normals empty when none
  std::vector<double> intensity;                 // empty when none
  bool normals_oriented = false;
};

// One update step of the ICP loop (Open3D's TransformationEstimation, with scale).
class SimilarityEstimation {
 public:
  virtual ~SimilarityEstimation() = default;
  virtual std::string Name() const = 0;
  // The similarity Δ to apply after the current estimate (X'' = Δ(X')) that best aligns the correspondences.
  virtual core::Sim3 Update(const IcpSource& source, const IcpTarget& target,
                            const std::vector<Correspondence>& correspondences, bool estimate_scale) const = 0;
  // The residual this estimation minimises, for one pair (target units; for reporting).
  virtual double Residual(const IcpSource& source, const IcpTarget& target, const Correspondence& c) const = 0;
};

class PointToPointEstimation : public SimilarityEstimation {
 public:
  std::string Name() const override { return "point-to-point"; }
  core::Sim3 Update(const IcpSource& source, const IcpTarget& target,
                    const std::vector<Correspondence>& correspondences, bool estimate_scale) const override;
  double Residual(const IcpSource& source, const IcpTarget& target, const Correspondence& c) const override;
};

class PointToPlaneEstimation : public SimilarityEstimation {
 public:
  // loss_scale in target spacings (0: automatic, see IcpOptions); colour_weight λ as in IcpOptions.
  PointToPlaneEstimation(RobustLoss loss = RobustLoss::kCauchy, double loss_scale = 0, double colour_weight = 0,
                         int lm_iterations = 10)
      : loss_(loss), loss_scale_(loss_scale), colour_weight_(colour_weight), lm_iterations_(lm_iterations) {}
  std::string Name() const override { return colour_weight_ > 0 ? "point-to-plane+colour" : "point-to-plane"; }
  core::Sim3 Update(const IcpSource& source, const IcpTarget& target,
                    const std::vector<Correspondence>& correspondences, bool estimate_scale) const override;
  double Residual(const IcpSource& source, const IcpTarget& target, const Correspondence& c) const override;

 private:
  RobustLoss loss_;
  double loss_scale_, colour_weight_;
  int lm_iterations_;
};

struct IcpResult {
  core::Sim3 transform;    // source → target
  bool converged = false;  // the tolerance was met before max_iterations
  int iterations = 0;
  size_t source_points = 0;    // used for the fit (after subsampling)
  size_t correspondences = 0;  // kept in the final evaluation
  double fitness = 0;          // correspondences / source_points
  double initial_rmse = 0;     // RMS of the estimation's residual (target units) at the start …
  double rmse = 0;             // … and at the end, over the kept correspondences
  double rmse_point = 0;       // RMS point-to-point distance at the end (includes sampling spacing)
  std::string estimation;      // the estimation's name
};

// Runs the loop from `initial`. Throws fmv3d::Error when the source is empty or fewer than 10
// correspondences survive (no overlap at this start). `estimation` defaults to PointToPlaneEstimation
// configured from the options.
IcpResult ScaledIcp(const io::OrientedPointCloud& source, const IcpTarget& target, const core::Sim3& initial,
                    const IcpOptions& options, const SimilarityEstimation* estimation = nullptr);

// a ∘ b: X ↦ a(b(X)).
core::Sim3 ComposeSim3(const core::Sim3& a, const core::Sim3& b);

}  // namespace fmv3d::align
