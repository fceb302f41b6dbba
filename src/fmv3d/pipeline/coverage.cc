#include "fmv3d/pipeline/coverage.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fmv3d/surface/poisson.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

namespace {

double Share(const cv::Mat& covered, const cv::Mat& non_sky) {
  const int n = cv::countNonZero(non_sky);
  if (n == 0) return 0;
  cv::Mat both;
  cv::bitwise_and(covered, non_sky, both);
  return static_cast<double>(cv::countNonZero(both)) / n;
}

}  // namespace

void CoverageOptions::Check() const {
  if (max_size < 32) throw Error("coverage: max_size must be at least 32 pixels");
  if (worst_views < 0) throw Error("coverage: worst_views must be >= 0");
}

cv::Mat SkyMask(const cv::Mat& bgr, double max_gradient, double min_brightness) {
  if (bgr.empty() || bgr.type() != CV_8UC3) throw Error("sky mask: expected an 8-bit colour image");
  cv::Mat grey, blurred, gx, gy, mag;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey, CV_32F, 1.0 / 255);
  cv::GaussianBlur(grey, blurred, cv::Size(5, 5), 0);
  cv::Sobel(blurred, gx, CV_32F, 1, 0, 3, 1.0 / 8);
  cv::Sobel(blurred, gy, CV_32F, 0, 1, 3, 1.0 / 8);
  cv::magnitude(gx, gy, mag);
  cv::Mat candidate(bgr.size(), CV_8U);
  for (int y = 0; y < bgr.rows; ++y)
    for (int x = 0; x < bgr.cols; ++x) {
      const cv::Vec3b& c = bgr.at<cv::Vec3b>(y, x);
      const bool ok = mag.at<float>(y, x) <= max_gradient && blurred.at<float>(y, x) >= min_brightness &&
                      static_cast<int>(c[0]) >= static_cast<int>(c[2]) - 16;
      candidate.at<uint8_t>(y, x) = ok ? 1 : 0;
    }
  // Keep the candidate regions that touch the top border.
  cv::Mat labels;
  const int n = cv::connectedComponents(candidate, labels, 4, CV_32S);
  std::vector<uint8_t> touches(static_cast<size_t>(n), 0);
  for (int x = 0; x < bgr.cols; ++x) {
    const int l = labels.at<int>(0, x);
    if (l > 0) touches[l] = 1;
  }
  cv::Mat sky(bgr.size(), CV_8U);
  for (int y = 0; y < bgr.rows; ++y)
    for (int x = 0; x < bgr.cols; ++x) sky.at<uint8_t>(y, x) = touches[labels.at<int>(y, x)] ? 255 : 0;
  return sky;
}

ViewCoverage ComputeViewCoverage(const cv::Mat& frame, const core::Camera& camera, const core::Pose& pose,
                                 const io::TexturedMesh* mesh, const io::OrientedPointCloud* cloud,
                                 double point_spacing, CoverageMaps* maps) {
  if (!mesh || mesh->faces.empty())
    return ComputeViewCoverageWith(frame, camera, pose, nullptr, cloud, point_spacing, maps);
  const render::Renderer renderer(*mesh);
  return ComputeViewCoverageWith(frame, camera, pose, &renderer, cloud, point_spacing, maps);
}

ViewCoverage ComputeViewCoverageWith(const cv::Mat& frame, const core::Camera& camera, const core::Pose& pose,
                                     const render::Renderer* mesh, const io::OrientedPointCloud* cloud,
                                     double point_spacing, CoverageMaps* maps) {
  if (frame.empty()) throw Error("coverage: empty frame");
  const int w = camera.width, h = camera.height;
  cv::Mat image;
  if (frame.cols != w || frame.rows != h)
    cv::resize(frame, image, cv::Size(w, h), 0, 0, cv::INTER_AREA);
  else
    image = frame;
  if (image.type() == CV_8UC1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
  ViewCoverage vc;
  CoverageMaps m;
  m.sky = SkyMask(image);
  cv::Mat mesh_depth;
  if (mesh && !mesh->mesh().faces.empty()) {
    render::RenderOptions o;
    o.supersample = 1;
    o.cull_backfaces = false;
    o.shading = false;
    o.near_plane = 1e-6;
    mesh_depth = mesh->Render(camera, pose, o).depth;
    m.mesh = mesh_depth > 0;
    m.sky.setTo(0, m.mesh);
  }
  if (cloud && !cloud->empty()) {
    m.dense = cv::Mat::zeros(h, w, CV_8U);
    const Eigen::Matrix3d R = pose.R();
    const double f = camera.fy();
    // Points are projected in parallel, bucketed per thread by row band, and drawn afterwards.
    const int bands = std::max(1, std::min(h, 64));
    std::vector<std::vector<cv::Vec3i>> by_band(static_cast<size_t>(bands));
    tbb::enumerable_thread_specific<std::vector<std::vector<cv::Vec3i>>> tls(
        [&] { return std::vector<std::vector<cv::Vec3i>>(static_cast<size_t>(bands)); });
    tbb::parallel_for(tbb::blocked_range<size_t>(0, cloud->size(), 1 << 15), [&](const tbb::blocked_range<size_t>& r) {
      auto& mine = tls.local();
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const Eigen::Vector3d x = R * cloud->positions[i] + pose.t;
        if (!(x.z() > 0)) continue;
        const Eigen::Vector2d uv = camera.Project(x);
        // Compared as doubles first: a point far outside the view projects beyond int's range.
        if (!(uv.x() >= 0 && uv.y() >= 0 && uv.x() < w && uv.y() < h)) continue;
        const int u = static_cast<int>(uv.x()), v = static_cast<int>(uv.y());
        if (!mesh_depth.empty()) {  // hidden behind the mesh
          const float d = mesh_depth.at<float>(v, u);
          if (d > 0 && x.z() > 1.05 * d + 2 * point_spacing) continue;
        }
        const int radius = std::clamp(static_cast<int>(std::lround(0.5 * f * point_spacing / x.z())), 0, 16);
        mine[static_cast<size_t>(v) * bands / h].push_back(cv::Vec3i(u, v, radius));
      }
    });
    for (auto& t : tls)
      for (int b = 0; b < bands; ++b) by_band[b].insert(by_band[b].end(), t[b].begin(), t[b].end());
    for (const auto& band : by_band)
      for (const auto& d : band) {
        if (d[2] == 0)
          m.dense.at<uint8_t>(d[1], d[0]) = 255;
        else
          cv::circle(m.dense, cv::Point(d[0], d[1]), d[2], cv::Scalar(255), cv::FILLED);
      }
  }
  cv::Mat non_sky;
  cv::bitwise_not(m.sky, non_sky);
  vc.sky_pixels = static_cast<size_t>(cv::countNonZero(m.sky));
  vc.non_sky_pixels = static_cast<size_t>(w) * h - vc.sky_pixels;
  if (!m.mesh.empty()) vc.mesh = Share(m.mesh, non_sky);
  if (!m.dense.empty()) vc.dense = Share(m.dense, non_sky);
  if (maps) *maps = std::move(m);
  return vc;
}

nlohmann::json CoverageReport::ToJson() const {
  nlohmann::json v = nlohmann::json::array();
  for (const auto& c : views)
    v.push_back({{"image", c.name},
                 {"image_id", c.image_id},
                 {"non_sky_pixels", c.non_sky_pixels},
                 {"sky_pixels", c.sky_pixels},
                 {"mesh", c.mesh < 0 ? nlohmann::json() : nlohmann::json(c.mesh)},
                 {"dense", c.dense < 0 ? nlohmann::json() : nlohmann::json(c.dense)}});
  return {{"median_mesh", median_mesh < 0 ? nlohmann::json() : nlohmann::json(median_mesh)},
          {"median_dense", median_dense < 0 ? nlohmann::json() : nlohmann::json(median_dense)},
          {"views", v},
          {"pictures", [&] {
             nlohmann::json p = nlohmann::json::array();
             for (const auto& pic : pictures) {
               const auto& c = views[pic.view];
               p.push_back({{"file", pic.file},
                            {"image", c.name},
                            {"mesh", c.mesh < 0 ? nlohmann::json() : nlohmann::json(c.mesh)},
                            {"dense", c.dense < 0 ? nlohmann::json() : nlohmann::json(c.dense)}});
             }
             return p;
           }()}};
}

CoverageReport ComputeWorkspaceCoverage(const fs::path& root, const CoverageOptions& options) {
  options.Check();
  const core::Workspace ws(root);
  ws.Require(ws.sparse_dir() / "images.txt", "sparse");
  const core::Reconstruction rec = io::ReadColmapText(ws.sparse_dir());
  io::TexturedMesh mesh;
  bool has_mesh = false;
  const fs::path obj = ws.mesh_dir() / "textured.obj", ply = ws.mesh_dir() / "poisson.ply";
  if (fs::exists(obj)) {
    mesh = io::ReadObj(obj);
    has_mesh = true;
  } else if (fs::exists(ply)) {
    mesh = surface::ReadMeshPly(ply).ToTexturedMesh();
    has_mesh = true;
  }
  io::OrientedPointCloud cloud;
  double spacing = 0;
  if (fs::exists(ws.dense_dir() / "fused.ply")) {
    cloud = io::ReadPointCloudPly(ws.dense_dir() / "fused.ply");
    cloud.normals = {};
    cloud.colors = {};
    cloud.visibility = {};
    cloud.sigma = {};
    spacing = surface::MedianPointSpacing(cloud.positions);
  }
  // One renderer for every view, of the geometry alone: mip-mapping a texture atlas per view took most of the
  // report's time on 12 MP photo sets.
  io::TexturedMesh geometry;
  if (has_mesh) {
    geometry.vertices = mesh.vertices;
    geometry.faces = mesh.faces;
    for (auto& f : geometry.faces) f = io::Face{{f.v[0], f.v[1], f.v[2]}};
  }
  const std::optional<render::Renderer> depth_renderer =
      has_mesh ? std::optional<render::Renderer>(std::in_place, geometry) : std::nullopt;
  const render::Renderer* depth = depth_renderer ? &*depth_renderer : nullptr;
  const io::OrientedPointCloud* points = cloud.empty() ? nullptr : &cloud;
  CoverageReport out;
  std::vector<double> mesh_shares, dense_shares;
  for (const auto& [id, im] : rec.images) {
    const fs::path frame_path = ws.frames_dir() / im.name;
    if (!fs::exists(frame_path)) {
      spdlog::warn("coverage: {} not found, view left out", frame_path.string());
      continue;
    }
    const cv::Mat frame = io::ReadImage(frame_path);
    const core::Camera cam = rec.cameras.at(im.camera_id).FitWithin(options.max_size);
    ViewCoverage vc = ComputeViewCoverageWith(frame, cam, im.pose, depth, points, spacing);
    vc.image_id = id;
    vc.name = im.name;
    if (vc.mesh >= 0) mesh_shares.push_back(vc.mesh);
    if (vc.dense >= 0) dense_shares.push_back(vc.dense);
    out.views.push_back(vc);
  }
  // -1: no view to measure (reported as null).
  out.median_mesh = mesh_shares.empty() ? -1 : core::Median(mesh_shares);
  out.median_dense = dense_shares.empty() ? -1 : core::Median(dense_shares);

  // The worst views, drawn side by side with their frames.
  std::vector<size_t> order(out.views.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  auto key = [&](const ViewCoverage& v) { return v.mesh >= 0 ? v.mesh : v.dense; };
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return key(out.views[a]) < key(out.views[b]); });
  const size_t n_pictures = std::min(order.size(), static_cast<size_t>(options.worst_views));
  if (n_pictures > 0 && (has_mesh || !cloud.empty())) {
    const fs::path dir = ws.report_dir() / "coverage";
    core::EnsureDirectory(dir);
    const std::optional<render::Renderer> textured_renderer =
        has_mesh ? std::optional<render::Renderer>(std::in_place, mesh) : std::nullopt;
    for (size_t k = 0; k < n_pictures; ++k) {
      const ViewCoverage& v = out.views[order[k]];
      const auto& im = rec.images.at(v.image_id);
      const core::Camera cam = rec.cameras.at(im.camera_id).FitWithin(options.max_size);
      cv::Mat frame = io::ReadImage(ws.frames_dir() / im.name);
      if (frame.type() == CV_8UC1) cv::cvtColor(frame, frame, cv::COLOR_GRAY2BGR);
      cv::resize(frame, frame, cv::Size(cam.width, cam.height), 0, 0, cv::INTER_AREA);
      CoverageMaps maps;
      ComputeViewCoverageWith(frame, cam, im.pose, depth, points, spacing, &maps);
      cv::Mat model(frame.size(), CV_8UC3, cv::Scalar(40, 32, 28));
      if (textured_renderer) {
        const render::Renderer& renderer = *textured_renderer;
        render::RenderOptions o;
        o.supersample = 1;
        o.cull_backfaces = false;
        o.near_plane = 1e-6;
        bool textured = false;
        for (const auto& mt : mesh.materials) textured = textured || !mt.texture.empty();
        o.shading = !textured;
        const Eigen::Vector3d to_eye = -(im.pose.R().transpose() * Eigen::Vector3d::UnitZ());
        o.sun_elevation_deg = std::asin(std::clamp(to_eye.z(), -0.99, 0.99)) * 180 / M_PI;
        o.sun_azimuth_deg = std::atan2(to_eye.x(), to_eye.y()) * 180 / M_PI;
        const render::RenderResult r = renderer.Render(cam, im.pose, o);
        r.image.copyTo(model, r.depth > 0);
      }
      const cv::Mat& covered = has_mesh ? maps.mesh : maps.dense;
      cv::Mat overlay = frame.clone();
      cv::Mat uncovered;
      cv::bitwise_or(covered, maps.sky, uncovered);
      cv::bitwise_not(uncovered, uncovered);
      cv::Mat red(frame.size(), CV_8UC3, cv::Scalar(0, 0, 255)), blue(frame.size(), CV_8UC3, cv::Scalar(255, 80, 0));
      cv::Mat tinted;
      cv::addWeighted(frame, 0.4, red, 0.6, 0, tinted);
      tinted.copyTo(overlay, uncovered);
      cv::addWeighted(frame, 0.5, blue, 0.5, 0, tinted);
      tinted.copyTo(overlay, maps.sky);
      cv::Mat row;
      cv::hconcat(std::vector<cv::Mat>{frame, model, overlay}, row);
      std::string stem = im.name;
      for (char& c : stem)
        if (c == '/' || c == '\\') c = '_';
      stem = fs::path(stem).stem().string();
      const std::string file = "coverage/" + stem + ".png";
      core::WriteAtomically(ws.report_dir() / file, [&](const fs::path& tmp) {
        if (!cv::imwrite(tmp.string(), row)) throw Error(tmp.string() + ": cannot write PNG");
      });
      out.pictures.push_back({file, order[k]});
    }
  }
  return out;
}

}  // namespace fmv3d::pipeline
