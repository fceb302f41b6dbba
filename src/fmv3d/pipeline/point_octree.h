// The level-of-detail octree behind the point tiles (tiles_stage.h): additive refinement, each point stored
// exactly once. A node with more points than the tile budget keeps a spatially uniform subsample (one point per
// occupied cell of a grid sized so that about `max_points_per_tile` cells are occupied) and hands the rest to its
// eight octants; a node within the budget (or at max_depth) keeps all its points. So the root alone is a coarse
// picture of the whole cloud, and each level adds detail where there is any.
//
// The points are reordered in place so that every node's own points, and every subtree's, are contiguous:
// memory is the points themselves (32 bytes each) plus one byte per point during a subsample; time is
// O(N · depth).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace fmv3d::pipeline {

struct TilePoint {
  Eigen::Vector3f position;
  Eigen::Vector3f normal;  // zero when the cloud has none
  uint8_t rgb[3] = {0, 0, 0};
  uint8_t views = 0;  // images that see the point (0: unknown)
  float sigma = 0;    // stated uncertainty along the normal, model units (0: unknown)
};

struct OctreeNode {
  size_t begin = 0, count = 0;  // its own points: points[begin, begin + count)
  size_t subtree_end = 0;       // its and its descendants' points: points[begin, subtree_end)
  Eigen::AlignedBox3f bounds;   // of the subtree's points
  Eigen::AlignedBox3f cell;     // the octree cell (a cube)
  int level = 0;
  std::string name;           // "0" for the root, then one octant digit per level ("0", "03", "037", ...)
  std::vector<int> children;  // indices into PointOctree::nodes
};

struct PointOctree {
  std::vector<TilePoint> points;
  std::vector<OctreeNode> nodes;  // nodes[0] is the root (absent for an empty cloud)
};

struct OctreeOptions {
  size_t max_points_per_tile = 50000;
  int max_depth = 16;
  // Throws fmv3d::Error for a budget below 64 or a depth outside [0, 30].
  void Check() const;
};

// Points with a non-finite coordinate are dropped.
PointOctree BuildPointOctree(std::vector<TilePoint> points, const OctreeOptions& options);

}  // namespace fmv3d::pipeline
