// The Reconstruction: cameras, registered images with their 2D points, and 3D points with their tracks.
// It is the one model every stage reads and writes (sfm builds it, mvs/align/geo consume it, io/colmap_model
// stores it as a COLMAP text model). Plain data plus a few consistency helpers; the algorithms live in sfm/.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"

namespace fmv3d::core {

constexpr int64_t kNoPoint3D = -1;

struct TrackElement {
  uint32_t image_id = 0;
  uint32_t point2d_idx = 0;
  bool operator==(const TrackElement& o) const { return image_id == o.image_id && point2d_idx == o.point2d_idx; }
};

struct Image {
  uint32_t id = 0;
  uint32_t camera_id = 0;
  std::string name;  // frame file name relative to the frames folder (stable across stages, see DESIGN.md)
  Pose pose;
  std::vector<Eigen::Vector2d> points2d;  // pixels, fmv3d/COLMAP convention (see camera.h)
  std::vector<int64_t> point3d_ids;       // same size as points2d; kNoPoint3D when not triangulated
};

struct Point3D {
  uint64_t id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Eigen::Matrix<uint8_t, 3, 1> rgb = Eigen::Matrix<uint8_t, 3, 1>::Zero();
  double error = 0;  // mean reprojection error, pixels
  std::vector<TrackElement> track;
};

struct Reconstruction {
  std::map<uint32_t, Camera> cameras;
  std::map<uint32_t, Image> images;
  std::map<uint64_t, Point3D> points;

  const Image* FindImageByName(const std::string& name) const;
  // Throws fmv3d::Error when ids or tracks do not refer to existing cameras, images or 2D points.
  void Validate() const;
  // Mean track length and mean reprojection error over all points (0 when empty).
  double MeanTrackLength() const;
  double MeanReprojectionError() const;
  // Applies a similarity to points and camera poses (e.g. to align to ground truth or a georeference).
  void Transform(const Sim3& sim);
};

}  // namespace fmv3d::core
