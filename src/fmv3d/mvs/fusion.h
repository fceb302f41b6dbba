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
// Before that, every map loses the foreground side of its depth discontinuities (edge_erosion_px > 0): a pixel
// with a pixel within edge_erosion_px whose depth is more than edge_depth_jump (relative) farther. PatchMatch's
// window straddles an occluding edge there and gives background pixels the foreground's plane ("fattening"):
// a roof or a facade continued up to a window radius past its real edge, and multi-view consistent, because
// neighbouring views fatten the same way. The same edge is kept from the views where it is not an occluding
// contour (both sides of a convex corner visible), so little true surface is lost. It is the mean of the consistent views' points; the pixels it used are
// marked so that the same surface is not emitted again from another view. Deterministic (views in id order).
#pragma once

#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/io/point_cloud.h"
#include "fmv3d/mvs/depth_map.h"
#include "fmv3d/mvs/view.h"

namespace fmv3d::mvs {

struct FusionOptions {
  int min_views = 3;                  // consistent views per point, the reference included
  double max_depth_error = 0.01;      // relative depth difference for agreement
  double max_reproj_error_px = 2.0;   // forward–backward reprojection error for agreement, reference pixels
  double max_normal_error_deg = 15;
  double visibility_margin = 0.03;    // relative depth beyond which a source "sees through" the point
  bool visibility_filter = true;
  int edge_erosion_px = 4;            // 0 = off; about PatchMatch's window radius
  double edge_depth_jump = 0.05;      // relative depth step that makes an occluding edge
  void Check() const;
};

// One view's map in compact form (fusion holds all of them: ~11 bytes per pixel).
struct FusionView {
  ViewGeometry geom;
  cv::Mat depth;   // CV_32F, 0 = none
  cv::Mat normal;  // CV_8SC3, world-frame unit normal · 127
  cv::Mat color;   // CV_8UC3 BGR, at the map's size
  std::vector<uint32_t> neighbours;  // image ids to check
};

// Converts a depth map (camera-frame normals) to the compact form.
FusionView MakeFusionView(const ViewGeometry& geom, const DepthMap& map, const cv::Mat& color,
                          std::vector<uint32_t> neighbours);

struct FusionStats {
  size_t candidates = 0;          // pixels with depth examined
  size_t rejected_support = 0;    // too few consistent views
  size_t rejected_visibility = 0; // free-space conflicts
  size_t edge_pixels = 0;         // pixels removed on the foreground side of depth discontinuities
  std::map<int, size_t> views_histogram;  // number of consistent views → points
};

// The mask (CV_8U, 255 = drop) of a depth map's pixels on the foreground side of its discontinuities (see
// above). Pixels without depth (0) are neither foreground nor background.
cv::Mat OccludingEdgeMask(const cv::Mat& depth, int radius_px, double depth_jump);

io::OrientedPointCloud FuseDepthMaps(const std::map<uint32_t, FusionView>& views, const FusionOptions& options,
                                     FusionStats* stats = nullptr);

}  // namespace fmv3d::mvs
