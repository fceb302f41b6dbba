// Fusion of per-view depth maps into oriented points (position, normal, colour, visibility list).
//
// Every pixel with a depth is lifted to a 3D point X and checked in the reference's neighbour views:
//  - consistent in view j: X projects onto a pixel whose depth agrees (relative error ≤ max_depth_error, and
//    j's point at that depth reprojects into the reference within max_reproj_error_px: the depth agreement
//    measured in pixels, which is what the matching resolved) and whose normal agrees (angle ≤
//    max_normal_error_deg);
//  - conflict in view j (the PMVS visibility filter): view j sees a surface clearly *behind* X through that
//    pixel, i.e. X floats in space that j sees through.
// A point is kept when at least min_views views (the reference included) are consistent and conflicts do not
// outnumber the supporting views.
//
// Before that, every map goes through the filters of map_filters.h: the pieces its own sparse points contradict
// (sparse_tolerance > 0: periodic texture matched one period off) and the foreground side of its occluding edges
// (edge_erosion_px > 0: PatchMatch's fattening).
//
// A fused point is the mean of the consistent views' points; the pixels it used are marked so that the same
// surface is not emitted again from another view. Deterministic (views in id order).
//
// Uncertainty filter (max_relative_uncertainty > 0): every fused point gets the first-order standard
// deviation of its position along its normal, as if triangulated from its consistent views. View i (unit ray
// d_i) fixes the point perpendicular to its ray to within σ_i = p_i · z_i / (f_i · |cos θ_i|):
//   - z_i / (f_i · |cos θ_i|): one pixel's footprint on the surface (depth z_i, focal f_i, θ_i the angle
//     between the ray and the normal): distance and grazing views make it large;
//   - p_i: how precisely a matching window can be located there, in pixels: the image-noise limit of
//     window matching (Cramér–Rao), ∝ 1 / sqrt(E) with E the gradient energy over the window that a gain-
//     and bias-invariant match (NCC) can use: the gradients' variance less the part a linear function of the
//     intensity explains (a smooth ramp shifted is the same ramp with another bias, so it fixes nothing).
//     Weak, blurred or ramp-like texture makes p_i large (TexturePrecisionMap; the unknown noise level
//     cancels below). Without a texture map p_i = 1.
// Then Λ = Σ_i (I − d_i d_iᵀ) / σ_i² and σ_n = sqrt(nᵀ Λ⁻¹ n), which also grows when the view directions
// are close together (small triangulation angle). The filter compares σ_n with the reference pixel's
// footprint at the point (depth / focal): that ratio says how well the point is resolved for its distance
// (triangulation angle, texture), not how far it is. Points whose ratio exceeds max_relative_uncertainty times
// the cloud's median ratio are dropped: low parallax for their distance or weak texture, which make the tail
// of the cloud's error distribution. Far surface resolved by a wide enough baseline is kept, with the large σ
// it states (below): the relative threshold does not depend on the scene's units, the working resolution or
// the image noise; COLMAP's and OpenMVS's filters on triangulation angle and view count aim at the same points
// with absolute thresholds.
//
// Stated σ (write_sigma): σ_n in world units, written per point (PLY property "sigma"). σ_n is known up to the
// common pixel-precision factor; the cloud measures that factor itself: for every point fused from two or more
// fresh pixels, the RMS spread of their points along the normal, and the scale is the median over the cloud of
// spread / σ_n. The stated σ is sigma_coverage × scale × σ_n: a bound that the true error along the normal
// exceeds in few cases (sigma_coverage 3: ≤ 5% on the synthetic scenes, bench/results/coverage.md, cover6.md).
// For the stated σ (not the filter) each p_i is floored: p_i' = hypot(p_i, p_0), p_0 the median p over the
// maps' pixels with a depth (texture_floor_quantile). Window matching reaches its noise limit only where the
// texture is weak; past the clip's typical texture, interpolation and the planar-patch model set the error,
// and an unfloored p made the sharpest, best-seen points the most overconfident (true error above the
// stated σ for 22% of the smallest-σ fifth of a town orbit's points, 0.4% of the largest). Far,
// grazing or low-parallax surface keeps its points with a large σ rather than being cut off by the depth range.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/io/point_cloud.h"
#include "fmv3d/mvs/depth_map.h"
#include "fmv3d/mvs/map_filters.h"
#include "fmv3d/mvs/view.h"

namespace fmv3d::mvs {

struct FusionOptions {
  int min_views = 3;                 // consistent views per point, the reference included
  double max_depth_error = 0.01;     // relative depth difference for agreement
  double max_reproj_error_px = 2.0;  // forward–backward reprojection error for agreement, reference pixels
  double max_normal_error_deg = 15;
  double visibility_margin = 0.03;  // relative depth beyond which a source "sees through" the point
  bool visibility_filter = true;
  int edge_erosion_px = 4;               // 0 = off; about PatchMatch's window radius
  double edge_depth_jump = 0.05;         // relative depth step that makes an occluding edge
  double max_relative_uncertainty = 10;  // 0 = off; drop points with σ_n / footprint > this · its median (above)
  bool write_sigma = true;               // compute and write each point's stated σ (above)
  double sigma_coverage = 3;             // stated σ = this × the measured per-point standard deviation
  double texture_floor_quantile = 0.5;   // p's matching floor: this quantile of p over the maps (0 = none)
  double sparse_tolerance = 0.05;        // 0 = off; relative depth within which a sparse point agrees (above)
  int sparse_min_votes = 3;              // disagreeing sparse points that can drop a map's piece
  void Check() const;
};

// One view's map in compact form (~13 bytes per pixel with the texture map and the used mask; fusion holds a
// bounded window of them, fusion_window.h).
struct FusionView {
  ViewGeometry geom;
  cv::Mat depth;                     // CV_32F, 0 = none
  cv::Mat normal;                    // CV_8SC3, world-frame unit normal · 127
  cv::Mat color;                     // CV_8UC3 BGR, at the map's size
  cv::Mat texture;                   // CV_16F, TexturePrecisionMap of the colour (empty: every pixel counts as 1 pixel)
  std::vector<uint32_t> neighbours;  // image ids to check
  std::vector<SparseObservation> sparse;  // the sparse points this view observed (its tracks)
};

// Converts a depth map (camera-frame normals) to the compact form.
FusionView MakeFusionView(const ViewGeometry& geom, const DepthMap& map, const cv::Mat& color,
                          std::vector<uint32_t> neighbours);

struct FusionStats {
  size_t candidates = 0;            // pixels with depth examined
  size_t rejected_support = 0;      // too few consistent views
  size_t rejected_visibility = 0;   // free-space conflicts
  size_t edge_pixels = 0;           // pixels removed on the foreground side of depth discontinuities
  size_t sparse_pieces = 0;         // map pieces dropped because the view's sparse points contradict them
  size_t sparse_pixels = 0;         // their pixels
  size_t rejected_uncertainty = 0;  // fused points dropped by the uncertainty filter
  double median_uncertainty = 0;    // median σ_n / footprint of the fused points before that filter (pixels, up to p)
  double max_uncertainty = 0;       // the threshold applied to σ_n / footprint (0 when the filter is off)
  double sigma_scale = 0;           // world units per unit of σ_n (stated σ, above); 0 when not measured
  double texture_floor = 0;         // p's matching floor (above); 0 when none
  std::map<int, size_t> views_histogram;  // number of consistent views → points
};

// σ_n of a point X with unit normal n seen by the given views (see above), with each view's pixel precision
// p_i (empty: 1 pixel each); infinity when the views do not constrain it (fewer than two distinct directions).
double NormalUncertainty(const Eigen::Vector3d& X, const Eigen::Vector3d& n,
                         const std::vector<const ViewGeometry*>& views, const std::vector<double>& pixel_sigma = {});

// p (see above) per pixel of a colour image (CV_8UC3), for matching windows of the given radius, up to a
// common factor: 1 / sqrt(E), E = mean over x and y of [var(g) − cov(g, I)² / var(I)] over the window (g the
// grey gradient component, I the grey level, 0..1); capped at 6e4 (flat windows). CV_16F.
cv::Mat TexturePrecisionMap(const cv::Mat& color, int radius_px);

io::OrientedPointCloud FuseDepthMaps(const std::map<uint32_t, FusionView>& views, const FusionOptions& options,
                                     FusionStats* stats = nullptr);

// The same points written straight to a PLY file (io::WritePointCloudPly's layout) without holding the cloud:
// the points go to a scratch file next to `ply` first, then the kept ones are copied behind the header. The
// maps are eroded in place (pass them with std::move). Returns the number of points written.
size_t FuseDepthMapsToPly(std::map<uint32_t, FusionView> views, const FusionOptions& options,
                          const std::filesystem::path& ply, FusionStats* stats = nullptr);

// The same from views loaded on demand into a bounded window (fusion_window.h): the same points, in the same
// order, whatever the window's capacity. The window's views are released before the PLY is assembled.
class FusionWindow;
size_t FuseDepthMapsToPly(FusionWindow& window, const FusionOptions& options, const std::filesystem::path& ply,
                          FusionStats* stats = nullptr);

}  // namespace fmv3d::mvs
