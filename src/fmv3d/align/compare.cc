#include "fmv3d/align/compare.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "fmv3d/align/compare_plots.h"
#include "fmv3d/align/error_mesh.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/surface/colored_mesh.h"

namespace fmv3d::align {
namespace {

ErrorStats Stats(const std::vector<double>& values) {
  ErrorStats s;
  if (values.empty()) return s;
  double sum = 0, sum2 = 0;
  for (double v : values) {
    sum += v;
    sum2 += v * v;
  }
  const double n = values.size();
  s.mean = sum / n;
  s.rms = std::sqrt(sum2 / n);
  s.std = std::sqrt(std::max(0.0, sum2 / n - s.mean * s.mean));
  std::vector<double> a(values.size());
  for (size_t i = 0; i < values.size(); ++i) a[i] = std::abs(values[i]);
  s.p50 = core::Quantile(a, 0.5);
  s.p90 = core::Quantile(a, 0.9);
  s.p99 = core::Quantile(a, 0.99);
  return s;
}

// Per CAD sample: seen by at least min_views cameras of the model (in front, inside the image, facing the
// camera, not hidden by the CAD itself in a depth map rendered at reduced resolution).
std::vector<char> SeenSamples(const io::TexturedMesh& cad, const std::vector<Eigen::Vector3d>& samples,
                              const std::vector<Eigen::Vector3d>& sample_normals, const core::Reconstruction& cameras,
                              double length, const CompareOptions& o) {
  std::vector<int> views(samples.size(), 0);
  render::Renderer renderer(cad);
  render::RenderOptions ro;
  ro.supersample = 1;
  ro.shading = false;
  ro.cull_backfaces = false;  // a CAD model need not be closed or consistently wound
  core::Progress progress("visibility", cameras.images.size());
  for (const auto& entry : cameras.images) {
    const core::Image& image = entry.second;  // a named reference: C++17 lambdas cannot capture a binding
    core::Camera cam = cameras.cameras.at(image.camera_id);
    const double k = std::min(1.0, double(o.max_render_size) / std::max(cam.width, 1));
    if (k < 1) {  // same field of view, fewer pixels
      cam.width = std::max(1, int(std::lround(cam.width * k)));
      cam.height = std::max(1, int(std::lround(cam.height * k)));
      cam.f *= k;
      cam.u0 *= k;
      cam.v0 *= k;
    }
    const render::RenderResult rr = renderer.Render(cam, image.pose, ro);
    const Eigen::Vector3d centre = image.pose.Centre();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const Eigen::Vector3d xc = image.pose.Transform(samples[i]);
        if (xc.z() <= ro.near_plane) continue;
        if (sample_normals[i].dot(centre - samples[i]) <= 0) continue;  // back side
        const Eigen::Vector2d uv = cam.Project(xc);
        if (!cam.InImage(uv, 0.5)) continue;
        const int col = std::min(cam.width - 1, int(uv.x())), row = std::min(cam.height - 1, int(uv.y()));
        const float d = rr.depth.at<float>(row, col);
        // The pixel's depth is of its centre: allow the surface slope across a pixel plus a little.
        const double tol = std::max(0.005 * length, 0.01 * xc.z());
        if (d > 0 && xc.z() <= d + tol) ++views[i];
      }
    });
    progress.Add();
  }
  progress.Finish();
  std::vector<char> seen(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) seen[i] = views[i] >= o.min_views;
  return seen;
}

// True when a PLY file declares faces (a mesh, not a point cloud).
bool PlyHasFaces(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  while (std::getline(in, line) && line.rfind("end_header", 0) != 0)
    if (line.rfind("element face", 0) == 0) return std::stol(line.substr(12)) > 0;
  return false;
}

// Points on the triangles (already in the CAD frame) with a vertex inside `box`: a barycentric grid with
// steps of at most `spacing` along the longest edge (vertices excluded: they are measured already).
std::vector<Eigen::Vector3d> SampleFaces(const std::vector<Eigen::Vector3d>& v,
                                         const std::vector<Eigen::Vector3i>& triangles, const Eigen::AlignedBox3d& box,
                                         double spacing) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& f : triangles) {
    const Eigen::Vector3d &a = v[f[0]], &b = v[f[1]], &c = v[f[2]];
    if (!box.contains(a) && !box.contains(b) && !box.contains(c)) continue;
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::min(64, static_cast<int>(std::ceil(longest / spacing)));
    if (n < 2) {
      out.push_back((a + b + c) / 3);
      continue;
    }
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        if ((i == 0 && j == 0) || i == n || j == n) continue;
        const double u = double(i) / n, w = double(j) / n;
        out.push_back(a + u * (b - a) + w * (c - a));
      }
  }
  return out;
}

}  // namespace

IcpOptions CompareOptions::DefaultIcpOptions() {
  IcpOptions o;
  o.trim_fraction = 0.9;  // the crop already removed most of what is not the object
  return o;
}

void CompareOptions::Check() const {
  if (!(length > 0)) throw Error("compare: --length (the characteristic length H, CAD units) must be > 0");
  if (!(crop_margin >= 0)) throw Error("compare: crop margin must be >= 0");
  if (!(ground_cut >= 0 && ground_cut < 1)) throw Error("compare: ground cut must be in [0, 1)");
  if (!(completeness_threshold > 0)) throw Error("compare: completeness threshold must be > 0");
  if (!(sample_spacing > 0)) throw Error("compare: sample spacing must be > 0");
  if (min_views < 1) throw Error("compare: min_views must be >= 1");
  if (max_render_size < 16) throw Error("compare: max_render_size must be >= 16");
  icp_options.Check();
  global_options.Check();
}

nlohmann::json ErrorStats::ToJson() const {
  return {{"mean_percent", 100 * mean},   {"std_percent", 100 * std},     {"rms_percent", 100 * rms},
          {"p50_abs_percent", 100 * p50}, {"p90_abs_percent", 100 * p90}, {"p99_abs_percent", 100 * p99}};
}

nlohmann::json CompareResult::ToJson() const {
  nlohmann::json j;
  j["length"] = length;
  j["units"] = "percent of length (H)";
  j["transform"] = Sim3ToJson(transform);
  j["coarse_alignment"] = coarse;
  if (icp) {
    j["icp"] = {{"estimation", icp->estimation},          {"converged", icp->converged},
                {"iterations", icp->iterations},          {"fitness", icp->fitness},
                {"rmse_before", icp->initial_rmse},       {"rmse_after", icp->rmse},
                {"correspondences", icp->correspondences}};
  } else {
    j["icp"] = nullptr;
  }
  j["points"] = {{"total", points_total}, {"measured", points_measured}, {"cropped", points_cropped}};
  j["error"] = {{"x", x.ToJson()}, {"y", y.ToJson()}, {"z", z.ToJson()}, {"total", total.ToJson()}};
  j["completeness_percent"] = 100 * completeness;
  j["completeness_threshold_percent"] = 100 * completeness_threshold;
  j["completeness_samples"] = surface_samples;
  j["completeness_seen_only"] = completeness_seen_only;
  j["completeness_from_faces"] = completeness_from_faces;
  return j;
}

CompareResult CompareToCad(const CompareOptions& options) {
  options.Check();
  if (!std::filesystem::exists(options.reconstruction)) throw Error(options.reconstruction.string() + ": no such file");
  if (!std::filesystem::exists(options.cad)) throw Error(options.cad.string() + ": no such file");
  const io::OrientedPointCloud recon = io::ReadPointCloudPly(options.reconstruction);
  const io::TexturedMesh cad = io::ReadObj(options.cad, /*load_textures=*/false);
  if (cad.faces.empty()) throw Error(options.cad.string() + ": no faces");
  std::vector<Eigen::Vector3i> triangles;
  // The mesh reader refuses any face naming a vertex the file does not have.
  if (PlyHasFaces(options.reconstruction)) triangles = surface::ReadMeshPly(options.reconstruction).triangles;
  return CompareToCad(recon, cad, options, triangles);
}

namespace {

// The CAD surface sampled at the requested spacing, with each sample's face normal.
struct CadSamples {
  std::vector<Eigen::Vector3d> points, normals;
  double spacing = 0;
};

CadSamples SampleCad(const geometry::MeshDistance& cad_distance, double H, const CompareOptions& o) {
  // A CAD much larger than H (a whole site) would need billions of samples at the requested spacing: cap
  // the count so memory stays bounded, and say so.
  double area = 0;
  for (size_t f = 0; f < cad_distance.num_triangles(); ++f) area += cad_distance.Area(static_cast<int>(f));
  constexpr double kMaxSamples = 4e6;
  CadSamples s;
  s.spacing = o.sample_spacing * H;
  if (area / (s.spacing * s.spacing) > kMaxSamples) {
    s.spacing = std::sqrt(area / kMaxSamples);
    spdlog::warn(
        "compare: the CAD surface ({:.0f} m²) is large for --length {}: surface samples {:.3f} apart "
        "instead of {:.3f} (completeness is coarser)",
        area, H, s.spacing, o.sample_spacing * H);
  }
  std::vector<int> faces;
  s.points = cad_distance.SampleSurface(s.spacing, &faces, 7);
  if (s.points.size() < 10) throw Error("compare: the CAD surface is too small for --length " + std::to_string(H));
  s.normals.resize(s.points.size());
  for (size_t i = 0; i < s.points.size(); ++i) s.normals[i] = cad_distance.Normal(faces[i]);
  return s;
}

// The reconstruction's points (and normals) mapped by `sim` that fall in the CAD's box grown by `margin`, above
// the ground cut.
io::OrientedPointCloud CropToCad(const io::OrientedPointCloud& recon, const core::Sim3& sim,
                                 const Eigen::AlignedBox3d& cad_box, double margin, double ground_z) {
  const Eigen::Vector3d m = Eigen::Vector3d::Constant(margin);
  Eigen::AlignedBox3d box(cad_box.min() - m, cad_box.max() + m);
  box.min().z() = ground_z;
  io::OrientedPointCloud out;
  for (size_t i = 0; i < recon.size(); ++i) {
    const Eigen::Vector3d p = sim.Apply(recon.positions[i]);
    if (!box.contains(p)) continue;
    out.positions.push_back(p);
    if (recon.has_normals()) out.normals.push_back((sim.q.cast<float>() * recon.normals[i]).normalized());
  }
  return out;
}

// Steps 1–2: the reconstruction onto the CAD — a given transform or global registration, then scaled ICP on the
// points near the CAD (a wider box: the start may be off).
core::Sim3 AlignToCad(const io::OrientedPointCloud& recon, const CadSamples& cs, const Eigen::AlignedBox3d& cad_box,
                      double ground_z, const CompareOptions& o, CompareResult& res) {
  const double H = o.length;
  core::Sim3 T;
  if (o.transform) {
    T = *o.transform;
    res.coarse = "transform";
  } else {
    io::OrientedPointCloud cad_cloud;
    cad_cloud.positions = cs.points;
    const GlobalRegistrationResult g = GlobalRegistration(recon, cad_cloud, o.global_options);
    T = g.transform;
    res.coarse = "global:" + g.method;
    spdlog::info("compare: global registration ({}), {:.1f}% of the points land on the CAD", g.method,
                 100 * g.inlier_fraction);
  }
  if (!o.icp) return T;
  const io::OrientedPointCloud near = CropToCad(recon, T, cad_box, std::max(o.crop_margin, 0.1) * H, ground_z);
  if (near.size() < 10)
    throw Error("compare: only " + std::to_string(near.size()) +
                " reconstructed points near the CAD model after the coarse alignment — check --transform");
  io::OrientedPointCloud cad_cloud;
  cad_cloud.positions = cs.points;
  for (const auto& n : cs.normals) cad_cloud.normals.push_back(n.cast<float>());
  const IcpTarget target(cad_cloud);
  IcpResult r = ScaledIcp(near, target, core::Sim3(), o.icp_options);
  spdlog::info("compare: ICP {} after {} iterations, RMS {:.4g} → {:.4g} ({:.3f}% → {:.3f}% of H), scale ×{:.6f}",
               r.converged ? "converged" : "stopped", r.iterations, r.initial_rmse, r.rmse, 100 * r.initial_rmse / H,
               100 * r.rmse / H, r.transform.s);
  res.icp = r;
  return ComposeSim3(r.transform, T);
}

// Per point: the error to the closest CAD point per axis and the signed distance, as fractions of H.
struct PointErrors {
  std::vector<double> x, y, z, signed_distance;
};

PointErrors MeasureErrors(const geometry::MeshDistance& cad_distance, const std::vector<Eigen::Vector3d>& pts,
                          double H) {
  PointErrors e;
  e.x.resize(pts.size());
  e.y.resize(pts.size());
  e.z.resize(pts.size());
  e.signed_distance.resize(pts.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, pts.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const geometry::ClosestPoint c = cad_distance.Closest(pts[i]);
      const Eigen::Vector3d d = (pts[i] - c.point) / H;
      e.x[i] = d.x();
      e.y[i] = d.y();
      e.z[i] = d.z();
      e.signed_distance[i] = c.signed_distance / H;
    }
  });
  return e;
}

// Step 4: the share of the CAD samples above the ground cut (and seen by the cameras, when given) that have a
// reconstructed point — or a point on the reconstruction's faces — within the completeness distance.
void MeasureCompleteness(const io::OrientedPointCloud& recon_in, const io::TexturedMesh& cad, const CadSamples& cs,
                         const io::OrientedPointCloud& pts, const core::Sim3& T,
                         const std::vector<Eigen::Vector3i>& triangles, double ground_z, const CompareOptions& o,
                         CompareResult& res) {
  const double H = o.length;
  const Eigen::AlignedBox3d cad_box = cad.Bounds();
  const std::vector<Eigen::Vector3d>& samples = cs.points;
  std::vector<char> counted(samples.size(), 1);
  for (size_t i = 0; i < samples.size(); ++i) counted[i] = samples[i].z() >= ground_z;
  if (!o.cameras.empty()) {
    const core::Reconstruction cams = io::ReadColmapText(o.cameras);
    if (cams.images.empty()) throw Error(o.cameras.string() + ": the model has no images");
    const std::vector<char> seen = SeenSamples(cad, samples, cs.normals, cams, H, o);
    for (size_t i = 0; i < samples.size(); ++i) counted[i] = counted[i] && seen[i];
    res.completeness_seen_only = true;
  }
  std::vector<Eigen::Vector3d> surface_points = pts.positions;
  if (!triangles.empty()) {
    std::vector<Eigen::Vector3d> all(recon_in.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = T.Apply(recon_in.positions[i]);
    const Eigen::Vector3d m = Eigen::Vector3d::Constant(o.crop_margin * H);
    Eigen::AlignedBox3d box(cad_box.min() - m, cad_box.max() + m);
    box.min().z() = ground_z;
    const auto on_faces = SampleFaces(all, triangles, box, o.sample_spacing * H);
    surface_points.insert(surface_points.end(), on_faces.begin(), on_faces.end());
    res.completeness_from_faces = true;
  }
  const PointIndex index(surface_points);
  const double thr2 = std::pow(o.completeness_threshold * H, 2);
  std::vector<char> covered(samples.size(), 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 2048), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) {
      if (!counted[i]) continue;
      double d2 = 0;
      covered[i] = index.Nearest(samples[i], &d2) >= 0 && d2 <= thr2;
    }
  });
  size_t n_counted = 0, n_covered = 0;
  for (size_t i = 0; i < samples.size(); ++i) {
    n_counted += counted[i] != 0;
    n_covered += covered[i] != 0;
  }
  res.surface_samples = n_counted;
  res.completeness_threshold = o.completeness_threshold;
  res.completeness = n_counted ? double(n_covered) / n_counted : 0;
}

// Step 5: histograms, top and side views, the CAD coloured by error, compare.json and compare.html.
void WriteCompareOutputs(const io::TexturedMesh& cad, const std::vector<Eigen::Vector3d>& pts, const PointErrors& e,
                         double spacing, const CompareOptions& o, const CompareResult& res) {
  const double H = o.length;
  core::EnsureDirectory(o.output_dir);
  PlotInput plot{cad, pts, e.x, e.y, e.z, e.signed_distance, H};
  WriteHistogramPlot(plot, o.output_dir / "histograms.png");
  WriteErrorView(plot, ViewDirection::kTop, o.output_dir / "top.png");
  WriteErrorView(plot, ViewDirection::kSide, o.output_dir / "side.png");
  nlohmann::json j = res.ToJson();
  j["reconstruction"] = o.reconstruction.string();
  j["cad"] = o.cad.string();
  j["crop_margin_percent"] = 100 * o.crop_margin;
  j["ground_cut_percent"] = 100 * o.ground_cut;
  if (!o.cameras.empty()) j["cameras"] = o.cameras.string();
  // The CAD coloured by the errors around each of its points (error_mesh.h): edges of two sample spacings,
  // errors from the points within the completeness distance (or two spacings), colours saturating at the
  // 90th percentile of |signed distance|.
  ErrorMeshOptions eo;
  eo.max_edge = 2 * spacing;
  eo.radius = std::max(o.completeness_threshold * H, 2 * spacing);
  eo.scale = std::max(res.total.p90, 1e-6);
  eo.length = H;
  const ErrorMesh em = BuildErrorMesh(cad, pts, e.signed_distance, eo);
  WriteErrorMeshPly(em, o.output_dir / "cad_error.ply");
  j["error_mesh"] = {{"file", "cad_error.ply"},
                     {"frame", "cad"},
                     {"vertices", em.vertices.size()},
                     {"triangles", em.triangles.size()},
                     {"covered_percent", 100 * em.covered_fraction},
                     {"radius_percent", 100 * eo.radius / H},
                     {"scale_percent", 100 * eo.scale}};
  core::WriteJson(o.output_dir / "compare.json", j);
  WriteCompareHtml(j, o.output_dir / "compare.html");
}

}  // namespace

CompareResult CompareToCad(const io::OrientedPointCloud& recon_in, const io::TexturedMesh& cad, const CompareOptions& o,
                           const std::vector<Eigen::Vector3i>& triangles) {
  o.Check();
  if (recon_in.empty()) throw Error("compare: the reconstruction has no points");
  cad.Validate();
  if (cad.faces.empty()) throw Error("compare: the CAD model has no faces");
  const double H = o.length;
  CompareResult res;
  res.length = H;
  res.points_total = recon_in.size();

  const geometry::MeshDistance cad_distance(cad);
  const CadSamples cs = SampleCad(cad_distance, H, o);
  const Eigen::AlignedBox3d cad_box = cad.Bounds();
  const double ground_z = cad_box.min().z() + o.ground_cut * H;
  const core::Sim3 T = AlignToCad(recon_in, cs, cad_box, ground_z, o, res);
  res.transform = T;

  // 3. Errors of the points inside the crop box.
  const io::OrientedPointCloud pts = CropToCad(recon_in, T, cad_box, o.crop_margin * H, ground_z);
  res.points_measured = pts.size();
  res.points_cropped = res.points_total - pts.size();
  if (pts.empty()) throw Error("compare: no reconstructed point lies within the CAD model's bounding box");
  const PointErrors e = MeasureErrors(cad_distance, pts.positions, H);
  res.x = Stats(e.x);
  res.y = Stats(e.y);
  res.z = Stats(e.z);
  res.total = Stats(e.signed_distance);

  MeasureCompleteness(recon_in, cad, cs, pts, T, triangles, ground_z, o, res);
  spdlog::info(
      "compare: {} of {} points measured; RMS {:.3f}% of H (x {:.3f}%, y {:.3f}%, z {:.3f}%), "
      "completeness {:.1f}%",
      res.points_measured, res.points_total, 100 * res.total.rms, 100 * res.x.rms, 100 * res.y.rms, 100 * res.z.rms,
      100 * res.completeness);
  if (!o.output_dir.empty()) WriteCompareOutputs(cad, pts.positions, e, cs.spacing, o, res);
  return res;
}

}  // namespace fmv3d::align
