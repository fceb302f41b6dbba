// Filters of a depth map before fusion (fusion.h): what PatchMatch gets wrong in ways that neighbouring views
// repeat, so that multi-view consistency alone does not remove it.
//
// Occluding edges: a map loses the foreground side of its depth discontinuities (edge_erosion_px > 0): a pixel
// with a pixel within edge_erosion_px whose depth is more than edge_depth_jump (relative) farther than the pixel
// and than the pixel's own plane puts the surface there (fusion uses the plane form below). PatchMatch's
// window straddles an occluding edge there and gives background pixels the foreground's plane ("fattening"):
// a roof or a facade continued up to a window radius past its real edge, and multi-view consistent, because
// neighbouring views fatten the same way. The same edge is kept from the views where it is not an occluding
// contour (both sides of a convex corner visible), so little true surface is lost.
//
// Sparse contradiction: a map loses its pieces that the view's own sparse points contradict (fusion's sparse_tolerance
// > 0). A piece is a connected region of the map whose neighbouring depths differ by at most edge_depth_jump
// (relative); a sparse point the view observed (its SfM track: the view saw that feature, at that pixel, at that depth)
// votes for the piece under its projection, agreeing when the map's depth there is within its tolerance of its own: the
// larger of sparse_tolerance and three times its own relative depth uncertainty, 1 / (f · sin α) per pixel of the view
// (α the widest angle between its track's rays), so that a far point triangulated from a short baseline does not
// overrule the map. A piece with at least sparse_min_votes disagreeing points and more disagreeing than agreeing ones
// is dropped. This is PatchMatch's failure on periodic texture (crop rows, tiles, facade grids): a region locked one
// period off in every source, multi-view consistent because its neighbouring views alias the same way — on a nadir
// flight, a patch of field tens of metres under the ground whose conflicts with the true ground then reject the true
// points instead. The verified tracks decide there; the pieces they do not reach (far field, untextured roofs) are
// untouched, and a true surface's piece holds its own agreeing points.
//
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/mvs/view.h"

namespace fmv3d::mvs {

// A sparse point a view observed: its position and the widest angle between its track's rays (radians).
struct SparseObservation {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  double parallax_rad = 0;
};

// The mask (CV_8U, 255 = drop) of a depth map's pixels on the foreground side of its discontinuities (see
// above). Pixels without depth (0) are neither foreground nor background.
cv::Mat OccludingEdgeMask(const cv::Mat& depth, int radius_px, double depth_jump);

// The same, with each pixel's own plane (its normal, `normal` CV_8SC3 world-frame × 127 as fusion holds it; `geom`
// the view's camera) as the reference instead of its depth: a neighbour is beyond an occluding edge when it is
// more than depth_jump farther than the pixel's plane puts the surface on its ray (and farther than the pixel
// itself). Ground seen at a grazing angle recedes by more than depth_jump within a few pixels yet follows its
// plane, so it is no edge; a fattened roof's plane does not reach the background behind it, so that is one.
// A plane that never meets the neighbour's ray in front of the camera is no evidence of an edge there.
cv::Mat OccludingEdgeMask(const cv::Mat& depth, const cv::Mat& normal, const ViewGeometry& geom, int radius_px,
                          double depth_jump);

// A sparse point in one map: its pixel, its camera-frame depth and the relative depth within which it agrees.
struct SparseDepth {
  double u = 0, v = 0, depth = 0, tolerance = 0;
};
// The same, for a view: the points that project into it in front of it, with the tolerance described above.
std::vector<SparseDepth> SparseDepthsIn(const ViewGeometry& geom, const std::vector<SparseObservation>& sparse,
                                        double min_tolerance);

// The mask (CV_8U, 255 = drop) of the pieces of a depth map that the sparse points contradict (see above).
// `pieces` (optional) receives how many pieces were dropped.
cv::Mat SparseContradictionMask(const cv::Mat& depth, const std::vector<SparseDepth>& sparse, double depth_jump,
                                int min_votes, size_t* pieces = nullptr);

}  // namespace fmv3d::mvs
