// Diagnostic (bench/results/sigma21.md): a fused cloud's stated σ against its true error, binned by depth, σ, σ/depth,
// consistent views and incidence, inside and outside truth.json's region; the nearest-point residuals of the SfM
// points (SPARSE) and the SfM points' own true error against the σ their track geometry implies (SPARSE TRUE).
//   sigdiag WS SYNTH_DIR          (ALT=1: σ scaled by sqrt(views / median); SPF=1: σ scaled by the SPARSE factor)
// Build: link against build/src/fmv3d/*.a as the fmv3d binary is (`ninja -C build -t commands fmv3d | tail -1`).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <unordered_map>
#include <vector>

#include "fmv3d/core/files.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/sfm/evaluation.h"
using namespace fmv3d;
struct P {
  double depth, sigma, dist, sdist, ncos, views, relsig;
  bool out;
};
static double Q(const std::vector<double>& v, double q) { return fmv3d::core::Quantile(v, q); }
static void Table(const char* name, std::vector<P>& ps, double (*key)(const P&), int bins) {
  std::vector<double> keys;
  for (auto& p : ps) keys.push_back(key(p));
  std::vector<double> edges;
  for (int b = 0; b <= bins; ++b) edges.push_back(Q(keys, b / double(bins)));
  edges.back() = 1e300;
  std::printf("== by %s\n%12s %12s %8s %8s %10s %10s %10s %10s %10s\n", name, "lo", "hi", "n", "exc%", "med d/s",
              "p95 d/s", "med sig", "med dist", "med sdist");
  for (int b = 0; b < bins; ++b) {
    std::vector<double> r, s, d, sd;
    size_t n = 0, over = 0;
    for (auto& p : ps) {
      double k = key(p);
      if (k < edges[b] || k >= edges[b + 1]) continue;
      ++n;
      over += p.dist > p.sigma;
      r.push_back(p.dist / p.sigma);
      s.push_back(p.sigma);
      d.push_back(p.dist);
      sd.push_back(p.sdist);
    }
    if (!n) continue;
    std::printf("%12.4g %12.4g %8zu %8.2f %10.3f %10.3f %10.4g %10.4g %10.4g\n", edges[b], edges[b + 1], n,
                100.0 * over / n, Q(r, .5), Q(r, .95), Q(s, .5), Q(d, .5), Q(sd, .5));
  }
}
int main(int argc, char** argv) {
  std::string ws = argv[1], tr = argv[2];
  auto est = io::ReadColmapText(ws + "/sparse");
  auto truth = io::ReadColmapText(tr + "/truth");
  auto scene = io::ReadObj(tr + "/scene.obj", false);
  auto tj = core::ReadJson(tr + "/truth.json");
  Eigen::AlignedBox3d region;
  if (tj.contains("bounds")) {
    auto& b = tj["bounds"];
    region = Eigen::AlignedBox3d(Eigen::Vector3d(b["min"][0], b["min"][1], b["min"][2]),
                                 Eigen::Vector3d(b["max"][0], b["max"][1], b["max"][2]));
  }
  auto cloud = io::ReadPointCloudPly(ws + "/dense/fused.ply");
  auto al = sfm::EvaluateSparse(est, truth).alignment;
  std::map<uint32_t, Eigen::Vector3d> centre;
  for (auto& [id, im] : est.images) centre[id] = al.Apply(im.pose.Centre());
  geometry::MeshDistance mesh(scene);
  size_t stride = std::max<size_t>(1, cloud.size() / 400000);
  std::vector<P> ps;
  for (size_t i = 0; i < cloud.size(); i += stride) {
    P p;
    Eigen::Vector3d x = al.Apply(cloud.positions[i]);
    auto c = mesh.Closest(x);
    p.dist = c.distance;
    p.sigma = cloud.sigma[i] * al.s;
    p.out = !region.isEmpty() && !region.contains(c.point);
    const auto& vis = cloud.visibility[i];
    p.views = vis.size();
    Eigen::Vector3d cc = centre.count(vis[0]) ? centre[vis[0]] : Eigen::Vector3d::Zero();
    p.depth = (x - cc).norm();
    Eigen::Vector3d ray = (c.point - cc).normalized();
    Eigen::Vector3d n = c.face >= 0 ? mesh.Normal(c.face) : Eigen::Vector3d::UnitZ();
    p.ncos = std::abs(ray.dot(n));
    p.sdist = (x - c.point).dot(ray);  // + : beyond the true surface along the ray
    p.relsig = p.sigma / p.depth;
    ps.push_back(p);
  }
  std::printf("points %zu (stride %zu), scale %.4f\n", ps.size(), stride, al.s);
  double fsp = 1;
  {  // sparse-point calibration: nearest fused point to each SfM point, residual along its normal / its sigma
    const double cell = std::atof(getenv("CELL") ? getenv("CELL") : "0.01");
    auto key = [&](const Eigen::Vector3d& x) {
      long a = std::floor(x.x() / cell), b = std::floor(x.y() / cell), c = std::floor(x.z() / cell);
      return (a * 73856093) ^ (b * 19349663) ^ (c * 83492791);
    };
    std::unordered_multimap<long, size_t> grid;
    for (size_t i = 0; i < cloud.size(); ++i) grid.emplace(key(cloud.positions[i]), i);
    std::vector<double> ratio, ratio_out;
    for (auto& [pid, pt] : est.points) {
      double best = 1e300;
      size_t bi = 0;
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            auto r = grid.equal_range(key(pt.xyz + cell * Eigen::Vector3d(dx, dy, dz)));
            for (auto it = r.first; it != r.second; ++it) {
              double d = (cloud.positions[it->second] - pt.xyz).norm();
              if (d < best) {
                best = d;
                bi = it->second;
              }
            }
          }
      if (best > cell) continue;
      const double rn = std::abs((pt.xyz - cloud.positions[bi]).dot(cloud.normals[bi].cast<double>()));
      const double rr = rn / cloud.sigma[bi];
      Eigen::Vector3d xt = al.Apply(pt.xyz);
      (region.isEmpty() || region.contains(xt) ? ratio : ratio_out).push_back(rr);
    }
    std::printf("SPARSE pairs %zu inside, %zu outside; median |r|/sigma %.3f (p95 %.3f), outside %.3f\n", ratio.size(),
                ratio_out.size(), Q(ratio, .5), Q(ratio, .95), Q(ratio_out, .5));
    std::vector<double> all = ratio;
    all.insert(all.end(), ratio_out.begin(), ratio_out.end());
    fsp = std::max(1.0, Q(all, .5) / 0.674 * 3);
    std::printf("SPARSE implied factor %.3f\n", fsp);
  }
  {  // sparse points' true error vs their modelled sigma
    std::vector<double> rat, dist_all, bs;
    for (auto& [pid, pt] : est.points) {
      std::vector<Eigen::Vector3d> rays;
      Eigen::Vector3d c0;
      for (auto& te : pt.track) {
        auto& im = est.images.at(te.image_id);
        rays.push_back((pt.xyz - im.pose.Centre()).normalized());
      }
      c0 = est.images.at(pt.track[0].image_id).pose.Centre();
      double widest = 0;
      for (size_t a = 0; a < rays.size(); ++a)
        for (size_t b = a + 1; b < rays.size(); ++b)
          widest = std::max(widest, std::acos(std::clamp(rays[a].dot(rays[b]), -1.0, 1.0)));
      const double f = est.cameras.at(est.images.at(pt.track[0].image_id).camera_id).f;
      const double sr = pt.error / std::sqrt(M_PI / 2) / f;
      Eigen::Vector3d xt = al.Apply(pt.xyz);
      auto c = mesh.Closest(xt);
      Eigen::Vector3d n = c.face >= 0 ? mesh.Normal(c.face) : Eigen::Vector3d::UnitZ();
      Eigen::Vector3d ray = pt.xyz - c0;
      double d = ray.norm();
      double ct = std::abs((al.q * ray).normalized().dot(n));
      double across = d * sr, along = across / std::max(std::sin(widest), 1e-6);
      double b = std::sqrt(std::pow(along * ct, 2) + across * across * std::max(0.0, 1 - ct * ct)) * al.s;
      rat.push_back(c.distance / b);
      dist_all.push_back(c.distance);
      bs.push_back(b);
    }
    std::printf(
        "SPARSE TRUE: n %zu, median true dist %.4g, median b %.4g, median dist/b %.3f (ideal 0.674), p95 %.3f\n",
        rat.size(), Q(dist_all, .5), Q(bs, .5), Q(rat, .5), Q(rat, .95));
  }
  if (getenv("SPF")) {
    for (auto& p : ps) {
      p.sigma *= fsp;
      p.relsig = p.sigma / p.depth;
    }
  }
  {
    size_t over = 0, n_out = 0, over_out = 0;
    for (auto& p : ps) {
      over += p.dist > p.sigma;
      if (p.out) {
        ++n_out;
        over_out += p.dist > p.sigma;
      }
    }
    std::printf("exceeded %.2f%%, outside %.2f%%\n", 100.0 * over / ps.size(),
                100.0 * over_out / std::max<size_t>(1, n_out));
  }
  if (getenv("ALT")) {
    std::vector<double> nv;
    for (auto& p : ps) nv.push_back(std::sqrt(p.views));
    const double med = Q(nv, 0.5);
    for (auto& p : ps) {
      p.sigma *= std::sqrt(p.views) / med;
      p.relsig = p.sigma / p.depth;
    }
    size_t over = 0;
    for (auto& p : ps) over += p.dist > p.sigma;
    std::printf("ALT sqrt(N/Nmed), median sqrt N %.3f: exceeded %.2f%%\n", med, 100.0 * over / ps.size());
  }
  for (int part = 0; part < 2; ++part) {
    std::vector<P> sub;
    for (auto& p : ps)
      if (p.out == (part == 1)) sub.push_back(p);
    std::printf("######## %s: %zu\n", part ? "OUTSIDE" : "INSIDE", sub.size());
    if (sub.empty()) continue;
    Table(
        "depth", sub, [](const P& p) { return p.depth; }, 8);
    Table(
        "sigma", sub, [](const P& p) { return p.sigma; }, 8);
    Table(
        "sigma/depth", sub, [](const P& p) { return p.relsig; }, 8);
    Table(
        "views", sub, [](const P& p) { return p.views; }, 6);
    Table(
        "|cos(ray,n)|", sub, [](const P& p) { return p.ncos; }, 6);
  }
}
