#include "fmv3d/surface/synthetic_cloud.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"

namespace fmv3d::surface {

void SyntheticCloudOptions::Check() const {
  if (!(spacing > 0)) throw Error("synthetic cloud: spacing must be positive");
  if (min_views < 1) throw Error("synthetic cloud: min_views must be >= 1");
  if (!(position_noise >= 0) || !(normal_noise_deg >= 0) || !(outlier_range >= 0) || !(max_distance >= 0))
    throw Error("synthetic cloud: noise, ranges and distances must be >= 0");
  if (!(outlier_share >= 0 && outlier_share < 1)) throw Error("synthetic cloud: outlier share must be in [0, 1)");
}

SyntheticCloud SampleOrientedCloud(const io::TexturedMesh& truth, const core::Reconstruction& cameras,
                                   const SyntheticCloudOptions& options) {
  options.Check();
  if (cameras.images.empty()) throw Error("synthetic cloud: no cameras");
  // Sample only the region of interest (a synthetic scene's far-ground ring is many times its size).
  std::vector<Eigen::Vector3i> tris;
  for (const auto& f : truth.faces) {
    Eigen::AlignedBox3d box;
    for (const int v : f.v) box.extend(truth.vertices[v]);
    if (options.region.isEmpty() || options.region.intersects(box)) tris.emplace_back(f.v[0], f.v[1], f.v[2]);
  }
  if (tris.empty()) throw Error("synthetic cloud: no surface inside the region");
  const geometry::MeshDistance surface(truth.vertices, std::move(tris));
  std::vector<int> faces;
  const std::vector<Eigen::Vector3d> samples = surface.SampleSurface(options.spacing, &faces, options.seed);
  const size_t n = samples.size();

  // Per sample: views that see it, and the colour of the nearest one.
  std::vector<std::vector<uint32_t>> views(n);
  std::vector<io::Rgb8> colors(n, io::Rgb8(0, 0, 0));
  std::vector<float> colour_depth(n, std::numeric_limits<float>::infinity());
  const render::Renderer renderer(truth);
  render::RenderOptions ro;
  ro.supersample = 1;
  for (const auto& entry : cameras.images) {  // named, not bound: C++17 lambdas cannot capture bindings
    const uint32_t id = entry.first;
    const auto& image = entry.second;
    const core::Camera& cam = cameras.cameras.at(image.camera_id);
    const render::RenderResult r = renderer.Render(cam, image.pose, ro);
    const Eigen::Vector3d centre = image.pose.Centre();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 8192), [&](const tbb::blocked_range<size_t>& range) {
      for (size_t i = range.begin(); i < range.end(); ++i) {
        const Eigen::Vector3d& p = samples[i];
        if (surface.Normal(faces[i]).dot(centre - p) <= 0) continue;  // back side
        const Eigen::Vector3d x = image.pose.Transform(p);
        if (x.z() <= 0) continue;
        if (options.max_distance > 0 && x.norm() > options.max_distance) continue;
        const Eigen::Vector2d uv = cam.Project(x);
        if (!cam.InImage(uv)) continue;
        const int col = std::min(cam.width - 1, static_cast<int>(uv.x()));
        const int row = std::min(cam.height - 1, static_cast<int>(uv.y()));
        const float d = r.depth.at<float>(row, col);
        // Depth test: the pixel centre is up to half a pixel off, so allow for the surface's slope.
        if (!(d > 0) || std::abs(d - x.z()) > 0.01 * x.z() + options.spacing) continue;
        views[i].push_back(id);
        if (x.z() < colour_depth[i]) {
          colour_depth[i] = static_cast<float>(x.z());
          const cv::Vec3b bgr = r.image.at<cv::Vec3b>(row, col);
          colors[i] = io::Rgb8(bgr[2], bgr[1], bgr[0]);
        }
      }
    });
  }

  SyntheticCloud out;
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const double tilt = options.normal_noise_deg * M_PI / 180.0;
  for (size_t i = 0; i < n; ++i) {
    if (static_cast<int>(views[i].size()) < options.min_views) continue;
    out.seen_surface.push_back(samples[i]);
    Eigen::Vector3d p = samples[i];
    Eigen::Vector3d normal = surface.Normal(faces[i]);
    if (options.position_noise > 0) p += options.position_noise * Eigen::Vector3d{gauss(rng), gauss(rng), gauss(rng)};
    if (tilt > 0) normal = (normal + tilt * Eigen::Vector3d{gauss(rng), gauss(rng), gauss(rng)}).normalized();
    if (options.outlier_share > 0 && (uniform(rng) + 1) / 2 < options.outlier_share) {
      const Eigen::Vector3d dir = Eigen::Vector3d{gauss(rng), gauss(rng), gauss(rng)}.normalized();
      p += options.outlier_range * uniform(rng) * dir;
    }
    out.cloud.positions.push_back(p);
    out.cloud.normals.push_back(normal.cast<float>());
    out.cloud.colors.push_back(colors[i]);
    out.cloud.visibility.push_back(std::move(views[i]));
  }
  return out;
}

SyntheticCloud PrepareSyntheticWorkspace(const std::filesystem::path& synth_dir, const std::filesystem::path& workspace,
                                         const SyntheticCloudOptions& options,
                                         const std::vector<std::string>& held_out) {
  namespace fs = std::filesystem;
  for (const char* need : {"frames", "truth/images.txt", "scene.obj"})
    if (!fs::exists(synth_dir / need))
      throw Error(synth_dir.string() + ": no " + need + " (not the output of `fmv3d synth` with png/jpg frames)");
  core::Reconstruction truth = io::ReadColmapText(synth_dir / "truth");
  for (const auto& name : held_out) {
    const core::Image* im = truth.FindImageByName(name);
    if (!im) throw Error(synth_dir.string() + ": no truth image named " + name);
    const uint32_t id = im->id;
    truth.images.erase(id);
  }
  truth.points.clear();  // tracks may name the held-out images; the surface stages do not read points
  for (auto& [id, im] : truth.images) std::fill(im.point3d_ids.begin(), im.point3d_ids.end(), core::kNoPoint3D);
  core::EnsureDirectory(workspace / "frames");
  core::EnsureDirectory(workspace / "sparse");
  core::EnsureDirectory(workspace / "dense");
  for (const auto& entry : fs::directory_iterator(synth_dir / "frames"))
    fs::copy_file(entry.path(), workspace / "frames" / entry.path().filename(), fs::copy_options::overwrite_existing);
  io::WriteColmapText(truth, workspace / "sparse");
  const io::TexturedMesh scene = io::ReadObj(synth_dir / "scene.obj");
  SyntheticCloud cloud = SampleOrientedCloud(scene, truth, options);
  io::WritePointCloudPly(cloud.cloud, workspace / "dense" / "fused.ply");
  return cloud;
}

MeshAccuracy EvaluateMesh(const ColoredMesh& mesh, const geometry::MeshDistance& truth,
                          const std::vector<Eigen::Vector3d>& seen_surface, double spacing, double tolerance) {
  MeshAccuracy acc;
  acc.tolerance = tolerance;
  if (mesh.empty()) return acc;
  const geometry::MeshDistance recon(mesh.vertices, mesh.triangles);
  const std::vector<Eigen::Vector3d> samples = recon.SampleSurface(spacing);
  std::vector<double> d(samples.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) d[i] = truth.Closest(samples[i]).distance;
  });
  acc.samples = d.size();
  if (!d.empty()) {
    double sum = 0, sum2 = 0;
    for (double v : d) sum += v, sum2 += v * v;
    acc.mean = sum / d.size();
    acc.rms = std::sqrt(sum2 / d.size());
    std::sort(d.begin(), d.end());
    acc.median = d[d.size() / 2];
    acc.p90 = d[std::min(d.size() - 1, static_cast<size_t>(0.9 * d.size()))];
    acc.max = d.back();
  }
  std::vector<char> near(seen_surface.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, seen_surface.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i)
      near[i] = recon.Closest(seen_surface[i], tolerance).distance <= tolerance;
  });
  size_t hits = 0;
  for (char c : near) hits += c;
  acc.completeness = seen_surface.empty() ? 0 : static_cast<double>(hits) / seen_surface.size();
  return acc;
}

}  // namespace fmv3d::surface
