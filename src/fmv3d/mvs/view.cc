#include "fmv3d/mvs/view.h"

#include <chrono>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/io/image_io.h"

namespace fmv3d::mvs {

bool ViewGeometry::Project(const Eigen::Vector3d& X, Eigen::Vector2d* uv, double* depth) const {
  const Eigen::Vector3d xc = R * X + t;
  if (!(xc.z() > 0)) return false;
  const Eigen::Vector3d p = K * xc;
  *uv = p.head<2>() / p.z();
  if (depth) *depth = xc.z();
  return true;
}

Eigen::Vector3d ViewGeometry::Unproject(const Eigen::Vector2d& uv, double z) const {
  const Eigen::Vector3d ray((uv.x() - K(0, 2)) / K(0, 0), (uv.y() - K(1, 2)) / K(1, 1), 1.0);
  return R.transpose() * (z * ray - t);
}

ViewGeometry MakeViewGeometry(const core::Reconstruction& rec, uint32_t image_id, int max_size) {
  const core::Image& im = rec.images.at(image_id);
  const core::Camera& cam = rec.cameras.at(im.camera_id);
  ViewGeometry g;
  g.image_id = image_id;
  g.name = im.name;
  const double scale =
      max_size > 0 ? std::min(1.0, static_cast<double>(max_size) / std::max(cam.width, cam.height)) : 1.0;
  g.width = std::max(1, static_cast<int>(std::lround(cam.width * scale)));
  g.height = std::max(1, static_cast<int>(std::lround(cam.height * scale)));
  const double sx = static_cast<double>(g.width) / cam.width, sy = static_cast<double>(g.height) / cam.height;
  g.K << cam.fx() * sx, 0, cam.u0 * sx, 0, cam.fy() * sy, cam.v0 * sy, 0, 0, 1;
  g.R = im.pose.R();
  g.t = im.pose.t;
  return g;
}

View LoadView(const core::Reconstruction& rec, const ViewGeometry& geom, const std::filesystem::path& frames_dir) {
  const core::Image& im = rec.images.at(geom.image_id);
  const core::Camera& cam = rec.cameras.at(im.camera_id);
  const auto path = frames_dir / im.name;
  if (!std::filesystem::exists(path))
    throw Error(path.string() + ": frame of registered image '" + im.name + "' not found");
  cv::Mat src = io::ReadImage(path);
  if (src.cols != cam.width || src.rows != cam.height)
    throw Error(path.string() + ": image is " + std::to_string(src.cols) + "x" + std::to_string(src.rows) +
                " but its camera in the sparse model is " + std::to_string(cam.width) + "x" +
                std::to_string(cam.height));
  const double sx = static_cast<double>(geom.width) / cam.width, sy = static_cast<double>(geom.height) / cam.height;
  // Shrink first (area filter, no aliasing), then undistort at the working resolution.
  if (geom.width != cam.width || geom.height != cam.height)
    cv::resize(src, src, cv::Size(geom.width, geom.height), 0, 0, cv::INTER_AREA);
  View v;
  v.geom = geom;
  if (cam.HasDistortion()) {
    cv::Mat map_x(geom.height, geom.width, CV_32F), map_y(geom.height, geom.width, CV_32F);
    const double fx = geom.K(0, 0), fy = geom.K(1, 1), cx = geom.K(0, 2), cy = geom.K(1, 2);
    for (int y = 0; y < geom.height; ++y) {
      for (int x = 0; x < geom.width; ++x) {
        const Eigen::Vector3d ray((x + 0.5 - cx) / fx, (y + 0.5 - cy) / fy, 1.0);
        const Eigen::Vector2d uv = cam.Project(ray);                    // original full-size pixels
        map_x.at<float>(y, x) = static_cast<float>(uv.x() * sx - 0.5);  // OpenCV: pixel centres at integers
        map_y.at<float>(y, x) = static_cast<float>(uv.y() * sy - 0.5);
      }
    }
    cv::Mat out;
    cv::remap(src, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0, 0, 0));
    src = out;
  }
  v.color = src;
  cv::Mat gray8;
  cv::cvtColor(src, gray8, cv::COLOR_BGR2GRAY);
  gray8.convertTo(v.gray, CV_32F, 1.0 / 255.0);
  return v;
}

ViewCache::ViewCache(const core::Reconstruction& rec, std::map<uint32_t, ViewGeometry> geoms,
                     std::filesystem::path frames_dir, size_t capacity)
    : rec_(rec),
      geoms_(std::move(geoms)),
      frames_dir_(std::move(frames_dir)),
      capacity_(std::max<size_t>(1, capacity)) {}

std::shared_ptr<const View> ViewCache::Get(uint32_t image_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = cache_.find(image_id);
  if (it != cache_.end()) {
    it->second.first = ++clock_;
    return it->second.second;
  }
  const auto start = std::chrono::steady_clock::now();
  auto view = std::make_shared<const View>(LoadView(rec_, geoms_.at(image_id), frames_dir_));
  load_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (cache_.size() >= capacity_) {
    auto oldest = cache_.begin();
    for (auto c = cache_.begin(); c != cache_.end(); ++c)
      if (c->second.first < oldest->second.first) oldest = c;
    cache_.erase(oldest);
  }
  cache_[image_id] = {++clock_, view};
  return view;
}

}  // namespace fmv3d::mvs
