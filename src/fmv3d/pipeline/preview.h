// Pictures of a reconstruction for the report: a virtual camera that frames the scene the way the flight saw
// it, point clouds drawn as z-buffered splats, camera positions as small frusta, meshes through our own
// rasteriser (render/). All images are CV_8UC3 BGR.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::pipeline {

struct View {
  core::Camera camera;
  core::Pose pose;
};

// An oblique view of the scene: from beyond the registered cameras (on the side of their mean centre,
// raised along the cameras' mean "up"), looking at the median of `points`, with a field of view that holds
// the middle 98% of them. Works in any model frame (SfM frames have arbitrary orientation and scale).
View SceneView(const core::Reconstruction& rec, const std::vector<Eigen::Vector3d>& points, int width, int height);

// Splats (radius in pixels) with a z-buffer on a dark background; colours RGB as stored in the cloud.
cv::Mat RenderPoints(const io::OrientedPointCloud& cloud, const View& view, int radius = 1);
// Draws each registered camera of `rec` as a small frustum (size relative to the scene) onto `image`.
void DrawCameras(cv::Mat& image, const core::Reconstruction& rec, const View& view, double size);
// The mesh through render::Renderer (textured when it has textures, else its colour/grey with sun shading).
cv::Mat RenderMesh(const io::TexturedMesh& mesh, const View& view);

// The sparse model's points as a cloud (for RenderPoints).
io::OrientedPointCloud SparseCloud(const core::Reconstruction& rec);

}  // namespace fmv3d::pipeline
