// Track completion guided by projection: every 3D point is projected into the registered images that could see
// it but do not observe it, and a keypoint near the projection joins its track when its descriptor looks like
// the track's own.
//
// Why: the correspondence graph only holds what the pairwise matcher kept. The ratio test drops a true match
// whenever an image has a similar-looking second candidate anywhere in it (repeated texture, the other
// orientation of the same keypoint), so a point seen by six images is often matched in four. Once the point and
// the cameras are known, the search for its keypoint in another image is local (a few pixels around the
// projection instead of the whole image), and the descriptor test only has to tell the point from the keypoints
// that happen to lie that close. Longer tracks tie the cameras together more tightly.
//
// Candidates: images that share a verified pair with one of the point's images (co-visible ones; a video's
// model is never projected into all its frames), registered, not yet in the track. A keypoint k is searched where
// it would fall with probability search_mass if it were the point's and the errors Gaussian: the ellipse
// rᵀ S⁻¹ r ≤ χ²₂(search_mass), S = σ_k² I + J Σ_X Jᵀ, with σ_k the noise of keypoints of k's scale (KeypointNoise)
// and Σ_X the point's covariance from its own observations, projected by the target view's Jacobian J. A fixed
// radius (the triangulator's outlier bound, several σ wide) lets chance keypoints of repeated texture in where the
// noise is a few tenths of a pixel; that bound stays as a cap. Only keypoints that observe no point are taken, the
// one most similar to the track's descriptors (smallest distance to any of them), unless a rival inside the cap
// looks about as similar (ratio test). The descriptor bound controls chance additions: every search is repeated
// at decoy locations a quarter to half an image away, where a keypoint is this point only by chance, and a
// candidate is accepted when it is closer than all but a false_accept_rate share of the decoys. A keypoint claimed
// by several points goes to the one it resembles most. After the caller's bundle adjustment, additions outside
// their bound are removed (RemoveAdditionsThatDoNotFit).
//
// Measured against true cameras, the additions are still off by > 1 px about twice as often as the matcher's own
// observations (keypoints near a projection look more alike than the decoys far away): the mapper runs this only
// when asked (MapperOptions::guided_completion).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/types.h"

namespace fmv3d::sfm {

struct GuidedCompletionOptions {
  double max_error_px = 4;          // cap on the search radius around the projection (pixels)
  double search_mass = 0.9973;      // probability mass of the search ellipse (χ²(2) 3σ-equivalent: ≈ 3.44σ)
  int min_bin_observations = 100;   // fewer in a scale bin: its keypoint noise is the model's overall one
  double false_accept_rate = 0.01;  // share of the decoy searches the descriptor bound lets through
  double ratio = 0.8;               // Lowe's ratio against a rival keypoint inside the cap (1: no ratio test)
  int decoys_per_projection = 8;    // decoy searches per projection (1 to 8)
  int min_decoys_for_bound = 200;   // fewer decoy searches found a keypoint: no bound is measured, nothing added
  void Check() const;
};

struct GuidedCompletionStats {
  size_t points = 0;            // points tried
  size_t projections = 0;       // (point, image) projections inside an image
  size_t candidates = 0;        // of those: with a free keypoint inside the radius
  size_t accepted = 0;          // observations added
  size_t ambiguous = 0;         // candidates with a rival about as similar (ratio test)
  size_t conflicts = 0;         // keypoints claimed by more than one point (the most similar one kept)
  size_t decoys = 0;            // decoy searches that found a keypoint (the bound's sample)
  double descriptor_bound = 0;  // squared L2 distance on the uint8 descriptors
  size_t member_distances = 0;  // observations of points with ≥ 2 described ones
  double member_median = 0;     // their median squared distance to the nearest fellow member (for the report)
  double sigma_px = 0;          // the model's keypoint noise per axis (all observations)
  double median_radius_px = 0;  // median over the projections of the search ellipse's major semi-axis
  std::vector<std::pair<uint64_t, core::TrackElement>> added;  // (point id, observation) of each addition
};

// Keypoint scales (SIFT scale, pixels) by image id; row k belongs to rec.images[id].points2d[k].
using KeypointScales = std::map<uint32_t, const std::vector<float>*>;

// Keypoint noise σ per axis (pixels) by detection scale: a detector locates a blob to a fraction of its size, so a
// large keypoint is noisier than a small one (Strecha sets and synthetic flights alike: the median error grows
// ~√2 per octave). σ per half-octave of scale from the median 2D reprojection error of the model's observations
// of that scale (Rayleigh for Gaussian errors: median σ·√(2 ln 2)), scaled up for the degrees of freedom the
// adjustment fitted (2 per observation, 3 per point, 6 per image: fitted residuals are smaller than the noise).
// Bins with fewer than min_observations, and keypoints of images without scales, take the σ of all observations.
class KeypointNoise {
 public:
  KeypointNoise(const core::Reconstruction& rec, const KeypointScales& scales, int min_observations);
  double Sigma(uint32_t image_id, uint32_t kp) const;
  double overall() const { return overall_; }  // 0: not measurable (too few observations)
  static constexpr int kBins = 12;             // half-octaves of scale from 1 px (below 1 px: the first)
  static int Bin(float scale);

 private:
  std::map<uint32_t, const std::vector<float>*> scales_;
  std::array<double, kBins> by_bin_{};
  double overall_ = 0;
};

// Covariance (px²) of a point's projection into image_id, from the point's observations with their keypoints' σ
// (cameras held). The search region of a keypoint k there is rᵀ S⁻¹ r ≤ χ²₂(search_mass), S = σ_k² I + this.
// Infinite entries when the point's observations do not determine it.
Eigen::Matrix2d ProjectedPointCovariance(const core::Reconstruction& rec, const core::Point3D& point, uint32_t image_id,
                                         const KeypointNoise& noise);

// Adds observations to the points of *rec. `descriptors` maps an image id to its descriptors (row k belongs to
// rec->images[id].points2d[k]; images without an entry are neither searched nor used for the bound);
// `covisible` maps an image id to the images it shares a verified pair with. Points and cameras are not moved:
// the caller's bundle adjustment follows.
GuidedCompletionStats CompleteTracksByProjection(core::Reconstruction* rec,
                                                 const std::map<uint32_t, const features::Descriptors*>& descriptors,
                                                 const std::map<uint32_t, std::set<uint32_t>>& covisible,
                                                 const GuidedCompletionOptions& options,
                                                 const KeypointScales& scales = {});

// After the adjustment that follows a completion: removes the added observations (of points that keep ≥ 2) whose
// reprojection error exceeds their image's search bound √χ²₂(search_mass)·σ_j (capped at max_error_px), σ_j from
// KeypointNoise on the adjusted model. Additions were chosen for being near the projection and carry no matcher
// evidence; one that the adjusted model does not explain as a keypoint of its noise is more likely a keypoint of
// chance than a member. Returns how many were removed.
size_t RemoveAdditionsThatDoNotFit(core::Reconstruction* rec,
                                   const std::vector<std::pair<uint64_t, core::TrackElement>>& added,
                                   const GuidedCompletionOptions& options, const KeypointScales& scales = {});

}  // namespace fmv3d::sfm
