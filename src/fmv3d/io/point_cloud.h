// OrientedPointCloud: the dense stage's product (DESIGN.md "dense/fused.ply") and the input of surface,
// align and geo — positions, unit normals, colours and, per point, the list of cameras (image ids of the
// sparse model) that see it.
//
// PLY layout written (binary little-endian, opened by Open3D, MeshLab, CloudCompare):
//   element vertex N
//   property float x, y, z          position (world units)
//   property float nx, ny, nz       unit normal, pointing towards the cameras that see the point
//   property uchar red, green, blue colour (RGB)
//   property float sigma            (when the cloud has it) the point's stated uncertainty along its normal,
//                                   world units (mvs/fusion.h says how it is calibrated); other tools ignore it
//   property list uchar int visibility   image ids that see the point (at most 255 kept)
// Positions are written as float; a cloud far from the origin should be expressed in a local frame first.
// The reader accepts any PLY (ascii or binary, either endianness) with at least x y z; normals, colours,
// sigma and visibility are empty when the file has none. Malformed files raise fmv3d::Error naming the file.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace fmv3d::io {

using Rgb8 = Eigen::Matrix<uint8_t, 3, 1>;

struct OrientedPointCloud {
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3f> normals;           // empty or one per point
  std::vector<Rgb8> colors;                       // RGB; empty or one per point
  std::vector<std::vector<uint32_t>> visibility;  // empty or one list of image ids per point
  std::vector<float> sigma;                       // empty or one uncertainty (world units) per point

  size_t size() const { return positions.size(); }
  bool empty() const { return positions.empty(); }
  bool has_normals() const { return !normals.empty(); }
  bool has_colors() const { return !colors.empty(); }
  bool has_visibility() const { return !visibility.empty(); }
  bool has_sigma() const { return !sigma.empty(); }
  void Reserve(size_t n);
  // Appends every attribute of `other`; attributes absent on either side are dropped from the result
  // (so the cloud stays consistent) unless this cloud is empty.
  void Append(const OrientedPointCloud& other);
  Eigen::AlignedBox3d Bounds() const;
  // Throws fmv3d::Error when an attribute array's size differs from the point count.
  void Validate() const;
};

void WritePointCloudPly(const OrientedPointCloud& cloud, const std::filesystem::path& path);
OrientedPointCloud ReadPointCloudPly(const std::filesystem::path& path);

}  // namespace fmv3d::io
