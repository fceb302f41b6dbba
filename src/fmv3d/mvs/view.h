// A registered frame prepared for stereo: undistorted to a pinhole camera and scaled to the working
// resolution, as grey (float, 0..1) for matching and colour for the fused points.
//
// Convention: pixel coordinates as in core/camera.h (origin at the top-left corner, pixel centre at +0.5);
// K maps a camera-frame point to such pixels. Pose is world-to-camera (x_cam = R X + t).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>

#include "fmv3d/core/reconstruction.h"

namespace fmv3d::mvs {

// Pinhole geometry of a view at the working resolution (no pixels).
struct ViewGeometry {
  uint32_t image_id = 0;
  std::string name;
  int width = 0, height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d Centre() const { return -R.transpose() * t; }
  // Pixel of a world point; false when it is not in front of the camera.
  bool Project(const Eigen::Vector3d& X, Eigen::Vector2d* uv, double* depth = nullptr) const;
  // World point seen through pixel uv at camera-frame depth z.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& uv, double z) const;
};

// Bytes a loaded View holds per pixel: grey (float) and colour (3 × uint8).
constexpr double kViewBytesPerPixel = 7;

struct View {
  ViewGeometry geom;
  cv::Mat gray;   // CV_32F in [0, 1]
  cv::Mat color;  // CV_8UC3, BGR
};

// The pinhole camera of an image at the working resolution: the longer side at most `max_size` pixels
// (0 = full size), focal lengths and principal point of the sparse model's camera scaled with the image.
ViewGeometry MakeViewGeometry(const core::Reconstruction& rec, uint32_t image_id, int max_size);

// Reads WS/frames/<name>, removes the lens distortion and resamples to the geometry's size. Throws
// fmv3d::Error when the frame is missing or its size differs from the camera's.
View LoadView(const core::Reconstruction& rec, const ViewGeometry& geom, const std::filesystem::path& frames_dir);

// Keeps the most recently used undistorted views in memory (views are streamed from disk, so memory stays
// bounded however many frames there are). Thread-safe.
class ViewCache {
 public:
  ViewCache(const core::Reconstruction& rec, std::map<uint32_t, ViewGeometry> geoms, std::filesystem::path frames_dir,
            size_t capacity);
  std::shared_ptr<const View> Get(uint32_t image_id);
  const ViewGeometry& Geometry(uint32_t image_id) const { return geoms_.at(image_id); }
  const std::map<uint32_t, ViewGeometry>& geometries() const { return geoms_; }
  double load_seconds() const { return load_seconds_; }
  size_t capacity() const { return capacity_; }

 private:
  const core::Reconstruction& rec_;
  std::map<uint32_t, ViewGeometry> geoms_;
  std::filesystem::path frames_dir_;
  size_t capacity_;
  std::mutex mutex_;
  std::map<uint32_t, std::pair<uint64_t, std::shared_ptr<const View>>> cache_;  // id → (last use, view)
  uint64_t clock_ = 0;
  double load_seconds_ = 0;
};

}  // namespace fmv3d::mvs
