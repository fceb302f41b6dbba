#include "fmv3d/pipeline/preview.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/render/renderer.h"

namespace fmv3d::pipeline {

using core::Median;

View SceneView(const core::Reconstruction& rec, const std::vector<Eigen::Vector3d>& points, int width, int height) {
  if (points.empty()) throw Error("preview: nothing to show (no points)");
  Eigen::Vector3d target;
  for (int k = 0; k < 3; ++k) {
    std::vector<double> c;
    c.reserve(points.size());
    for (const auto& p : points) c.push_back(p[k]);
    target[k] = Median(c);
  }
  // Mean camera centre and mean "up" (image −y in world); without cameras look down from +z.
  Eigen::Vector3d mean_centre = Eigen::Vector3d::Zero(), up = Eigen::Vector3d::Zero();
  for (const auto& [id, im] : rec.images) {
    mean_centre += im.pose.Centre();
    up += im.pose.R().transpose() * Eigen::Vector3d(0, -1, 0);
  }
  std::vector<double> dist;
  for (const auto& p : points) dist.push_back((p - target).norm());
  std::sort(dist.begin(), dist.end());
  double radius = std::max(dist[std::min(dist.size() - 1, dist.size() * 98 / 100)], 1e-9);
  // The cameras belong in the picture too (an orbit's ring around the target).
  for (const auto& [id, im] : rec.images) radius = std::max(radius, (im.pose.Centre() - target).norm());
  Eigen::Vector3d dir;  // from target towards the eye
  if (rec.images.empty() || up.norm() < 1e-9) {
    up = Eigen::Vector3d::UnitY();
    dir = Eigen::Vector3d::UnitZ();
  } else {
    mean_centre /= rec.images.size();
    up.normalize();
    dir = mean_centre - target;
    // An orbit's mean centre is above the target: keep the side, add elevation for an oblique look.
    dir -= dir.dot(up) * up;
    if (dir.norm() < 1e-6 * radius) {
      // Nadir flights: look from the side the first camera is on.
      dir = rec.images.begin()->second.pose.Centre() - target;
      dir -= dir.dot(up) * up;
      if (dir.norm() < 1e-9) dir = up.unitOrthogonal();
    }
    dir = (dir.normalized() + up).normalized();  // 45° elevation
  }
  View v;
  const double fov_half = 0.5;  // radians of the half field of view along the shorter side
  const double distance = radius / std::sin(fov_half) * 1.05;
  v.camera = core::Camera::Pinhole(width, height, 0.5 * std::min(width, height) / std::tan(fov_half));
  v.pose = core::Pose::LookAt(target + distance * dir, target, up);
  return v;
}

cv::Mat RenderPoints(const io::OrientedPointCloud& cloud, const View& view, int radius) {
  const int w = view.camera.width, h = view.camera.height;
  cv::Mat image(h, w, CV_8UC3, cv::Scalar(40, 32, 28));
  std::vector<float> zbuf(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
  const Eigen::Matrix3d R = view.pose.R();
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3d x = R * cloud.positions[i] + view.pose.t;
    if (x.z() <= 0) continue;
    const double u = view.camera.fx() * x.x() / x.z() + view.camera.u0;
    const double v = view.camera.fy() * x.y() / x.z() + view.camera.v0;
    const int cu = static_cast<int>(std::floor(u)), cv_ = static_cast<int>(std::floor(v));
    cv::Vec3b bgr(200, 200, 200);
    if (cloud.has_colors()) bgr = cv::Vec3b(cloud.colors[i][2], cloud.colors[i][1], cloud.colors[i][0]);
    for (int dy = -radius + 1; dy < radius; ++dy)
      for (int dx = -radius + 1; dx < radius; ++dx) {
        const int px = cu + dx, py = cv_ + dy;
        if (px < 0 || py < 0 || px >= w || py >= h) continue;
        float& z = zbuf[static_cast<size_t>(py) * w + px];
        if (x.z() < z) {
          z = static_cast<float>(x.z());
          image.at<cv::Vec3b>(py, px) = bgr;
        }
      }
  }
  return image;
}

void DrawCameras(cv::Mat& image, const core::Reconstruction& rec, const View& view, double size) {
  const Eigen::Matrix3d R = view.pose.R();
  auto project = [&](const Eigen::Vector3d& X, cv::Point2d* p) {
    const Eigen::Vector3d x = R * X + view.pose.t;
    if (x.z() <= 1e-9) return false;
    *p = {view.camera.fx() * x.x() / x.z() + view.camera.u0, view.camera.fy() * x.y() / x.z() + view.camera.v0};
    return true;
  };
  for (const auto& [id, im] : rec.images) {
    const auto cam_it = rec.cameras.find(im.camera_id);
    if (cam_it == rec.cameras.end()) continue;
    const core::Camera& c = cam_it->second;
    const Eigen::Matrix3d Rt = im.pose.R().transpose();
    const Eigen::Vector3d C = im.pose.Centre();
    // Frustum corners at depth `size` through the image corners.
    const double hw = 0.5 * c.width / c.fx(), hh = 0.5 * c.height / c.fy();
    const Eigen::Vector3d corners[4] = {
        C + size * Rt * Eigen::Vector3d(-hw, -hh, 1), C + size * Rt * Eigen::Vector3d(hw, -hh, 1),
        C + size * Rt * Eigen::Vector3d(hw, hh, 1), C + size * Rt * Eigen::Vector3d(-hw, hh, 1)};
    cv::Point2d pc, pk[4];
    if (!project(C, &pc)) continue;
    bool ok = true;
    for (int k = 0; k < 4; ++k) ok = ok && project(corners[k], &pk[k]);
    if (!ok) continue;
    const cv::Scalar colour(60, 200, 255);
    for (int k = 0; k < 4; ++k) {
      cv::line(image, pc, pk[k], colour, 1, cv::LINE_AA);
      cv::line(image, pk[k], pk[(k + 1) % 4], colour, 1, cv::LINE_AA);
    }
  }
}

cv::Mat RenderMesh(const io::TexturedMesh& mesh, const View& view) {
  render::Renderer renderer(mesh);
  render::RenderOptions o;
  o.supersample = 2;
  o.cull_backfaces = false;  // reconstructed meshes are not guaranteed to be wound outwards
  o.near_plane = 1e-6;
  bool textured = false;
  for (const auto& m : mesh.materials) textured = textured || !m.texture.empty();
  o.shading = !textured;
  // The mesh frame's "up" is unknown (SfM): light from the viewer's side so the shape reads.
  const Eigen::Vector3d to_eye = -(view.pose.R().transpose() * Eigen::Vector3d::UnitZ());
  o.sun_elevation_deg = std::asin(std::clamp(to_eye.z(), -0.99, 0.99)) * 180 / M_PI;
  o.sun_azimuth_deg = std::atan2(to_eye.x(), to_eye.y()) * 180 / M_PI;
  // The renderer scales light so that a level surface shows its albedo; lit from a low viewer, that gain would
  // saturate every face turned to the viewer to white. Here a face turned to the light shows its albedo instead.
  if (o.shading) o.exposure = o.ambient + (1 - o.ambient) * std::max(std::sin(o.sun_elevation_deg * M_PI / 180), 0.05);
  cv::Mat image = renderer.Render(view.camera, view.pose, o).image;
  return image;
}

io::OrientedPointCloud SparseCloud(const core::Reconstruction& rec) {
  io::OrientedPointCloud c;
  for (const auto& [id, p] : rec.points) {
    c.positions.push_back(p.xyz);
    c.colors.push_back(p.rgb);
  }
  return c;
}

}  // namespace fmv3d::pipeline
