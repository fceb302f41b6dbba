#include "fmv3d/mvs/evaluation.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <unordered_map>

#include "fmv3d/core/error.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/sfm/evaluation.h"

namespace fmv3d::mvs {
namespace {

// Uniform voxel hash of points for "is there a point within r" queries (cell size = r).
class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3d>& pts, double cell) : pts_(pts), cell_(cell) {
    for (size_t i = 0; i < pts.size(); ++i) grid_[Key(Cell(pts[i]))].push_back(static_cast<uint32_t>(i));
  }
  bool AnyWithin(const Eigen::Vector3d& p, double r) const {
    const Eigen::Vector3i c = Cell(p);
    const double r2 = r * r;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          auto it = grid_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == grid_.end()) continue;
          for (uint32_t i : it->second)
            if ((pts_[i] - p).squaredNorm() <= r2) return true;
        }
    return false;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return {static_cast<int>(std::floor(p.x() / cell_)), static_cast<int>(std::floor(p.y() / cell_)),
            static_cast<int>(std::floor(p.z() / cell_))};
  }
  static uint64_t Key(const Eigen::Vector3i& c) {
    return (static_cast<uint64_t>(c.x() & 0x1FFFFF) << 42) | (static_cast<uint64_t>(c.y() & 0x1FFFFF) << 21) |
           static_cast<uint64_t>(c.z() & 0x1FFFFF);
  }
  const std::vector<Eigen::Vector3d>& pts_;
  double cell_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> grid_;
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::lround(q * static_cast<double>(v.size() - 1))));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

struct CompletenessResult {
  size_t surface_samples = 0, seen_samples = 0, complete_samples = 0;
  double completeness = 0, sample_spacing = 0;
  std::vector<Eigen::Vector3d> missed;  // when opt.keep_missed
};

// Completeness of `pts` (truth frame) over the surface of `mesh` inside `region` (empty: everywhere) that
// min_cameras true cameras see; `breakdown` (optional) gets the per-orientation and per-camera-count parts.
CompletenessResult Completeness(const std::vector<Eigen::Vector3d>& pts, const geometry::MeshDistance& mesh,
                                const io::TexturedMesh& scene, const core::Reconstruction& truth,
                                double characteristic_length, const Eigen::AlignedBox3d& region,
                                const DenseEvaluationOptions& opt, std::vector<DenseBreakdown>* breakdown_out) {
  auto horizontal = [](const Eigen::Vector3d& n) { return std::abs(n.z()) >= 0.8; };
  std::vector<DenseBreakdown> dummy(9);
  std::vector<DenseBreakdown>& breakdown = breakdown_out ? *breakdown_out : dummy;
  // Completeness over the surface two or more true cameras see.
  // Sample only the triangles of the region (their centroid inside it).
  std::vector<Eigen::Vector3i> region_tris;
  double area = 0;
  for (size_t f = 0; f < mesh.num_triangles(); ++f) {
    const auto& tri = mesh.triangles()[f];
    const Eigen::Vector3d c = (mesh.vertices()[tri[0]] + mesh.vertices()[tri[1]] + mesh.vertices()[tri[2]]) / 3;
    if (region.isEmpty() || region.contains(c)) {
      area += mesh.Area(static_cast<int>(f));
      region_tris.push_back(tri);
    }
  }
  if (region_tris.empty()) throw Error("evaluate-dense: no surface of the true mesh inside the evaluation region");
  const geometry::MeshDistance region_mesh(mesh.vertices(), region_tris);
  const double sample_spacing = std::max(opt.min_spacing_fraction * characteristic_length,
                                         std::sqrt(area / static_cast<double>(opt.max_surface_samples)));
  std::vector<int> faces;
  const auto samples = region_mesh.SampleSurface(sample_spacing, &faces, 7);
  std::vector<std::atomic<uint16_t>> seen(samples.size());
  for (auto& s : seen) s = 0;
  const render::Renderer renderer(scene);
  render::RenderOptions ro;
  ro.supersample = 1;
  ro.shading = false;
  for (const auto& entry : truth.images) {  // named, not bound: C++17 lambdas cannot capture bindings
    const auto& im = entry.second;
    const core::Camera cam = truth.cameras.at(im.camera_id).FitWithin(opt.render_max_size);
    const cv::Mat depth = renderer.Render(cam, im.pose, ro).depth;
    tbb::parallel_for(size_t{0}, samples.size(), [&](size_t i) {
      const Eigen::Vector3d xc = im.pose.Transform(samples[i]);
      if (!(xc.z() > 0)) return;
      const Eigen::Vector3d view_dir = (im.pose.Centre() - samples[i]).normalized();
      if (region_mesh.Normal(faces[i]).dot(view_dir) <= 0) return;  // back side of the face
      const Eigen::Vector2d uv = cam.Project(xc);
      // Compared as doubles first: a point far outside the view projects beyond int's range.
      if (!(uv.x() >= 0 && uv.y() >= 0 && uv.x() < cam.width && uv.y() < cam.height)) return;
      const int u = static_cast<int>(uv.x()), v = static_cast<int>(uv.y());
      const float d = depth.at<float>(v, u);
      // Tolerance: the pixel footprint on a slanted surface plus a share of the length.
      const double tol = 0.01 * characteristic_length + 3 * xc.z() / cam.f;
      if (d > 0 && std::abs(d - xc.z()) <= tol) seen[i]++;
    });
  }
  const double radius = opt.completeness_fraction * characteristic_length;
  const PointGrid grid(pts, radius);
  std::atomic<size_t> n_seen{0}, n_complete{0};
  std::vector<uint8_t> complete(samples.size(), 0);
  tbb::parallel_for(size_t{0}, samples.size(), [&](size_t i) {
    if (seen[i] < opt.min_cameras) return;
    n_seen++;
    if (grid.AnyWithin(samples[i], radius)) n_complete++, complete[i] = 1;
  });
  for (size_t i = 0; i < samples.size(); ++i) {
    if (seen[i] < opt.min_cameras) continue;
    const int by_orientation = horizontal(region_mesh.Normal(faces[i])) ? 4 : 5;
    const int by_cameras = seen[i] <= 3 ? 6 : (seen[i] <= 7 ? 7 : 8);
    for (int part : {by_orientation, by_cameras}) {
      breakdown[part].seen_samples++;
      breakdown[part].complete_samples += complete[i];
    }
  }
  CompletenessResult r;
  if (opt.keep_missed)
    for (size_t i = 0; i < samples.size(); ++i)
      if (seen[i] >= opt.min_cameras && !complete[i]) r.missed.push_back(samples[i]);
  r.surface_samples = samples.size();
  r.seen_samples = n_seen;
  r.complete_samples = n_complete;
  r.completeness = n_seen ? static_cast<double>(n_complete) / static_cast<double>(n_seen) : 0.0;
  r.sample_spacing = sample_spacing;
  return r;
}

}  // namespace

void DenseEvaluationOptions::Check() const {
  if (!(completeness_fraction > 0)) throw Error("evaluate-dense: completeness fraction must be positive");
  if (min_cameras < 1) throw Error("evaluate-dense: min_cameras must be at least 1");
  if (max_surface_samples < 100 || max_accuracy_points < 100) throw Error("evaluate-dense: too few samples");
  if (render_max_size < 32) throw Error("evaluate-dense: render_max_size must be at least 32");
}

nlohmann::json DenseEvaluation::ToJson() const {
  return {
      {"points", points},
      {"characteristic_length", characteristic_length},
      {"accuracy",
       {{"median", median_error},
        {"p90", p90_error},
        {"mean", mean_error},
        {"rms", rms_error},
        {"rms_percent_of_length", 100 * rms_error / characteristic_length},
        {"median_percent_of_length", 100 * median_fraction()},
        {"p90_percent_of_length", 100 * p90_fraction()},
        {"within_1_percent_of_length", within_1_percent}}},
      {"accuracy_in_region",
       {{"points", region_points},
        {"median", region_median_error},
        {"p90", region_p90_error},
        {"rms", region_rms_error},
        {"rms_percent_of_length", 100 * region_rms_error / characteristic_length},
        {"median_percent_of_length", 100 * region_median_error / characteristic_length}}},
      {"sigma",
       {{"exceeded", sigma_exceeded < 0 ? nlohmann::json() : nlohmann::json(sigma_exceeded)},
        {"exceeded_outside_region",
         sigma_exceeded_outside < 0 ? nlohmann::json() : nlohmann::json(sigma_exceeded_outside)},
        {"median", median_sigma}}},
      {"completeness",
       {{"fraction", completeness},
        {"fraction_everywhere", completeness_everywhere},
        {"seen_everywhere", seen_samples_everywhere},
        {"surface_samples", surface_samples},
        {"seen_by_2_cameras", seen_samples},
        {"complete_samples", complete_samples},
        {"sample_spacing", sample_spacing}}},
      {"breakdown",
       [&] {
         nlohmann::json b = nlohmann::json::array();
         for (const auto& d : breakdown)
           b.push_back({{"part", d.name},
                        {"points", d.points},
                        {"median_percent_of_length", 100 * d.median_error / characteristic_length},
                        {"p90_percent_of_length", 100 * d.p90_error / characteristic_length},
                        {"seen_samples", d.seen_samples},
                        {"complete_samples", d.complete_samples}});
         return b;
       }()},
      {"alignment", {{"scale", alignment.s}, {"translation", {alignment.t.x(), alignment.t.y(), alignment.t.z()}}}}};
}

DenseEvaluation EvaluateDense(const io::OrientedPointCloud& cloud, const core::Reconstruction& estimate,
                              const core::Reconstruction& truth, const io::TexturedMesh& scene,
                              double characteristic_length, const DenseEvaluationOptions& opt) {
  opt.Check();
  if (cloud.empty()) throw Error("evaluate-dense: the fused cloud has no points");
  if (!(characteristic_length > 0)) throw Error("evaluate-dense: characteristic length must be positive");
  DenseEvaluation ev;
  ev.points = cloud.size();
  ev.characteristic_length = characteristic_length;
  ev.alignment = sfm::EvaluateSparse(estimate, truth).alignment;

  // Points in the truth frame, evenly thinned for the accuracy figures.
  std::vector<Eigen::Vector3d> pts(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) pts[i] = ev.alignment.Apply(cloud.positions[i]);
  const geometry::MeshDistance mesh(scene);
  const size_t stride = (pts.size() + opt.max_accuracy_points - 1) / opt.max_accuracy_points;
  std::vector<double> dist((pts.size() + stride - 1) / stride);
  std::vector<int> part_of(dist.size());  // breakdown part of each evaluated point
  auto horizontal = [](const Eigen::Vector3d& n) { return std::abs(n.z()) >= 0.8; };
  tbb::parallel_for(size_t{0}, dist.size(), [&](size_t k) {
    const auto c = mesh.Closest(pts[k * stride]);
    dist[k] = c.distance;
    const bool inside = opt.region.isEmpty() || opt.region.contains(c.point);
    part_of[k] = (inside ? 0 : 2) + (c.face >= 0 && horizontal(mesh.Normal(c.face)) ? 0 : 1);
  });
  ev.breakdown = {{"points inside, horizontal surface"},
                  {"points inside, vertical/slanted surface"},
                  {"points outside region, horizontal"},
                  {"points outside region, vertical/slanted"},
                  {"samples horizontal"},
                  {"samples vertical/slanted"},
                  {"samples seen by 2-3 cameras"},
                  {"samples seen by 4-7 cameras"},
                  {"samples seen by 8+ cameras"}};
  for (int part = 0; part < 4; ++part) {
    std::vector<double> d;
    for (size_t k = 0; k < dist.size(); ++k)
      if (part_of[k] == part) d.push_back(dist[k]);
    ev.breakdown[part].points = d.size() * stride;
    ev.breakdown[part].median_error = Quantile(d, 0.5);
    ev.breakdown[part].p90_error = Quantile(d, 0.9);
  }
  {
    std::vector<double> d;
    double s2 = 0;
    for (size_t k = 0; k < dist.size(); ++k)
      if (part_of[k] < 2) d.push_back(dist[k]), s2 += dist[k] * dist[k];
    ev.region_points = d.size() * stride;
    ev.region_median_error = Quantile(d, 0.5);
    ev.region_p90_error = Quantile(d, 0.9);
    ev.region_rms_error = d.empty() ? 0 : std::sqrt(s2 / static_cast<double>(d.size()));
  }
  double sum = 0, sum2 = 0;
  size_t within = 0;
  for (double d : dist) {
    sum += d;
    sum2 += d * d;
    within += d <= 0.01 * characteristic_length;
  }
  ev.mean_error = sum / static_cast<double>(dist.size());
  ev.rms_error = std::sqrt(sum2 / static_cast<double>(dist.size()));
  if (cloud.has_sigma()) {
    size_t n_all = 0, over_all = 0, n_out = 0, over_out = 0;
    std::vector<double> sig(dist.size());
    for (size_t k = 0; k < dist.size(); ++k) {
      sig[k] = static_cast<double>(cloud.sigma[k * stride]) * ev.alignment.s;
      const bool over = dist[k] > sig[k];
      ++n_all, over_all += over;
      if (part_of[k] >= 2) ++n_out, over_out += over;
    }
    ev.sigma_exceeded = static_cast<double>(over_all) / static_cast<double>(std::max<size_t>(n_all, 1));
    if (n_out > 0) ev.sigma_exceeded_outside = static_cast<double>(over_out) / static_cast<double>(n_out);
    ev.median_sigma = Quantile(sig, 0.5);
  }
  ev.within_1_percent = static_cast<double>(within) / static_cast<double>(dist.size());
  ev.median_error = Quantile(dist, 0.5);
  ev.p90_error = Quantile(dist, 0.9);

  // Completeness over the surface two or more true cameras see: in the modelled region, and everywhere.
  const auto in_region = Completeness(pts, mesh, scene, truth, characteristic_length, opt.region, opt, &ev.breakdown);
  ev.surface_samples = in_region.surface_samples;
  ev.seen_samples = in_region.seen_samples;
  ev.complete_samples = in_region.complete_samples;
  ev.completeness = in_region.completeness;
  ev.sample_spacing = in_region.sample_spacing;
  ev.missed_samples = in_region.missed;
  if (opt.region.isEmpty()) {
    ev.completeness_everywhere = ev.completeness;
    ev.seen_samples_everywhere = ev.seen_samples;
  } else {
    const auto all = Completeness(pts, mesh, scene, truth, characteristic_length, Eigen::AlignedBox3d(), opt, nullptr);
    ev.completeness_everywhere = all.completeness;
    ev.seen_samples_everywhere = all.seen_samples;
  }
  return ev;
}

}  // namespace fmv3d::mvs
