// The rasteriser in one file (over 500 lines): face set-up, the visibility raster and shading share the per-face
// plane matrices and the per-thread buffers, and are the inner loop of every synthetic frame, so they stay
// together where the compiler sees them whole.
#include "fmv3d/render/renderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>

#include "fmv3d/core/error.h"

namespace fmv3d::render {
namespace {

constexpr int kBandRows = 16;  // visibility-raster rows per work item

// Counter-based random numbers: the noise of a pixel depends only on (seed, index), so it is identical for
// any thread count or schedule.
inline uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
// Approximately standard-normal noise: the sum of four 16-bit uniforms from one hash (Irwin–Hall),
// rescaled to unit variance. Per-pixel Box–Muller (log, cos) cost a fifth of the frame time.
inline float Gaussian(uint64_t seed, uint64_t index) {
  const uint64_t h = SplitMix(seed ^ SplitMix(index));
  const uint32_t sum = static_cast<uint32_t>(h & 0xFFFF) + static_cast<uint32_t>((h >> 16) & 0xFFFF) +
                       static_cast<uint32_t>((h >> 32) & 0xFFFF) + static_cast<uint32_t>(h >> 48);
  return (static_cast<float>(sum) * (1.0f / 65536.0f) - 2.0f) * 1.7320508f;
}

// A face prepared for rasterisation: its (near-clipped) outline in visibility-raster coordinates, the
// sample box it covers and its inverse depth w = 1/z = A·X + B·Y + C over the raster.
struct Prim {
  std::array<Eigen::Vector2d, 4> p;
  int n = 0;  // 0 = not drawn
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
  double A = 0, B = 0, C = 0;
};

// Fast log2 for mip selection (max error ~0.01).
inline float FastLog2(float x) {
  int e;
  const float f = std::frexp(x, &e);  // x = f·2^e, f in [0.5, 1)
  const float m = 2.0f * f;           // x = m·2^(e−1), m in [1, 2)
  return static_cast<float>(e - 1) + (-0.34484843f * m + 2.02466578f) * m - 0.67487759f;
}

// The nearest of the candidate faces whose plane the ray d crosses inside the triangle; -1 when all
// candidates are empty (sky) and -2 when faces were offered but none contains the ray.
inline int ContainingFace(const std::vector<Eigen::Matrix3d>& planes, const int32_t* cand, int n,
                          const Eigen::Vector3d& d) {
  int best = -1;
  double best_s = 0;
  bool any = false;
  for (int k = 0; k < n; ++k) {
    const int f = cand[k];
    if (f < 0 || f == best) continue;
    any = true;
    const Eigen::Vector3d bm = planes[f] * d;
    const double s = bm.sum();
    if (!(s > 0)) continue;
    const double tol = -1e-9 * s;
    if (bm[0] < tol || bm[1] < tol || bm[2] < tol) continue;
    if (best < 0 || s > best_s || (s == best_s && f < best)) {
      best = f;
      best_s = s;
    }
  }
  if (best < 0 && any) return -2;
  return best;
}

// Sky colour along the ray d (camera frame; Rt turns it into the world frame): a gradient from the horizon
// up, haze below it.
Eigen::Vector3f SkyColour(const Eigen::Matrix3d& Rt, const Eigen::Vector3d& d) {
  const Eigen::Vector3d w = (Rt * d).normalized();
  const float e = static_cast<float>(w.z());
  if (e < 0) return {150.0f, 160.0f, 165.0f};                           // beyond the edge of the world: haze
  const Eigen::Vector3f horizon(235, 225, 212), zenith(205, 150, 100);  // BGR
  const float a = std::min(1.0f, std::sqrt(e));
  return (1 - a) * horizon + a * zenith;
}

// One (clipped) triangle v of face f into the visibility raster rows [by0, by1] of one band: edge functions
// with a top-left rule, so a sample on an edge shared by two faces goes to exactly one of them.
void RasteriseTriangle(const Prim& pr, std::array<Eigen::Vector2d, 3> v, int f, int by0, int by1, int vw,
                       std::vector<float>& wbuf, std::vector<int32_t>& ibuf) {
  const double area = (v[1] - v[0]).x() * (v[2] - v[0]).y() - (v[1] - v[0]).y() * (v[2] - v[0]).x();
  if (area == 0 || !std::isfinite(area)) return;
  if (area < 0) std::swap(v[1], v[2]);
  double ex[3], ey[3], ec[3];
  bool tie[3];
  for (int e = 0; e < 3; ++e) {
    const Eigen::Vector2d& a = v[e];
    const Eigen::Vector2d& b = v[(e + 1) % 3];
    const double dx = b.x() - a.x(), dy = b.y() - a.y();
    // E(p) = dx·(p.y − a.y) − dy·(p.x − a.x) > 0 inside; shared edges go to exactly one side.
    ex[e] = -dy;
    ey[e] = dx;
    ec[e] = dy * a.x() - dx * a.y();
    tie[e] = dy > 0 || (dy == 0 && dx < 0);
  }
  const double txmin = std::min({v[0].x(), v[1].x(), v[2].x()});
  const double txmax = std::max({v[0].x(), v[1].x(), v[2].x()});
  const double tymin = std::min({v[0].y(), v[1].y(), v[2].y()});
  const double tymax = std::max({v[0].y(), v[1].y(), v[2].y()});
  const int X0 = std::max(pr.x0, static_cast<int>(std::ceil(txmin - 0.5)));
  const int X1 = std::min(pr.x1, static_cast<int>(std::floor(txmax - 0.5)));
  const int Y0 = std::max({pr.y0, by0, static_cast<int>(std::ceil(tymin - 0.5))});
  const int Y1 = std::min({pr.y1, by1, static_cast<int>(std::floor(tymax - 0.5))});
  for (int Y = Y0; Y <= Y1; ++Y) {
    const double py = Y + 0.5, px0 = X0 + 0.5;
    double e0 = ex[0] * px0 + ey[0] * py + ec[0];
    double e1 = ex[1] * px0 + ey[1] * py + ec[1];
    double e2 = ex[2] * px0 + ey[2] * py + ec[2];
    double w = pr.A * px0 + pr.B * py + pr.C;
    float* wrow = &wbuf[size_t(Y) * vw];
    int32_t* irow = &ibuf[size_t(Y) * vw];
    for (int X = X0; X <= X1; ++X) {
      if ((e0 > 0 || (e0 == 0 && tie[0])) && (e1 > 0 || (e1 == 0 && tie[1])) && (e2 > 0 || (e2 == 0 && tie[2]))) {
        const float wf = static_cast<float>(w);
        if (wf > wrow[X] || (wf == wrow[X] && f < irow[X])) {
          wrow[X] = wf;
          irow[X] = f;
        }
      }
      e0 += ex[0];
      e1 += ex[1];
      e2 += ex[2];
      w += pr.A;
    }
  }
}

}  // namespace

// Per-face shading planes: for the ray d, s = m·d = 1/z, and u·s, v·s and light·s are linear in d too
// (texture coordinates and per-vertex light interpolated with perspective-correct barycentrics).
struct detail::ShadePlane {
  Eigen::Vector3d m;
  Eigen::Vector3f pu, pv, pl;
};
using detail::ShadePlane;

// Buffers reused across frames rendered by the same thread (page faults on fresh 30 MB buffers cost more
// than clearing them).
struct Renderer::Scratch {
  std::vector<Eigen::Vector3d> vc;
  std::vector<Prim> prims;
  std::vector<Eigen::Matrix3d> planes;
  std::vector<ShadePlane> shade;
  std::vector<float> wbuf;
  std::vector<int32_t> ibuf;
  std::vector<std::vector<int>> bins;
};

// Normalised rays for every output pixel centre and sub-sample, and the visibility raster's pinhole.
// Without distortion the raster is exactly the S×S supersampled output grid and rays are computed on the
// fly; with distortion the rays come from Camera::Unproject and are tabulated once per camera.
struct Renderer::RayTable {
  std::array<double, core::kNumIntrinsics> params{};
  int width = 0, height = 0, S = 1;
  bool distorted = false;
  int vw = 0, vh = 0;
  double fvx = 0, fvy = 0, cu = 0, cv = 0;
  std::vector<Eigen::Vector2d> centre;  // W·H (distorted only)
  std::vector<Eigen::Vector2f> sub;     // W·H·S² (distorted only), sample (a, b) of pixel at [S·S·p + b·S + a]
  std::vector<int32_t> sub_cell;        // raster cell of each sub-sample, -1 outside (distorted only)
};

void RenderOptions::Check() const {
  if (supersample < 1 || supersample > 4) throw Error("render: supersample must be 1..4");
  if (!(exposure > 0) || !std::isfinite(exposure)) throw Error("render: exposure must be positive");
  if (!(ambient >= 0 && ambient <= 1)) throw Error("render: ambient must be in [0, 1]");
  if (!(noise_sigma >= 0) || !std::isfinite(noise_sigma)) throw Error("render: noise sigma must be >= 0");
  if (!(sun_elevation_deg > -90 && sun_elevation_deg <= 90)) throw Error("render: sun elevation must be in (-90, 90]");
  if (!std::isfinite(sun_azimuth_deg)) throw Error("render: sun azimuth must be finite");
  if (!(near_plane > 0)) throw Error("render: near plane must be positive");
}

Eigen::Vector3d RenderOptions::SunDirection() const {
  const double az = sun_azimuth_deg * M_PI / 180, el = sun_elevation_deg * M_PI / 180;
  return {std::cos(el) * std::sin(az), std::cos(el) * std::cos(az), std::sin(el)};
}

Renderer::Renderer(const io::TexturedMesh& mesh) : mesh_(mesh) {
  mesh_.Validate();
  textures_.resize(mesh_.materials.size());
  tbb::parallel_for(size_t(0), mesh_.materials.size(), [&](size_t m) {
    if (!mesh_.materials[m].texture.empty()) textures_[m] = MipTexture(mesh_.materials[m].texture);
  });
  face_normals_.resize(mesh_.faces.size());
  for (size_t i = 0; i < mesh_.faces.size(); ++i) face_normals_[i] = mesh_.FaceNormal(i);
}

Renderer::~Renderer() = default;

std::shared_ptr<const Renderer::RayTable> Renderer::Rays(const core::Camera& camera, int S) const {
  const auto params = camera.Params();
  {
    std::lock_guard<std::mutex> lock(cache_mutex_);
    if (ray_cache_ && ray_cache_->params == params && ray_cache_->width == camera.width &&
        ray_cache_->height == camera.height && ray_cache_->S == S)
      return ray_cache_;
  }
  auto t = std::make_shared<RayTable>();
  t->params = params;
  t->width = camera.width;
  t->height = camera.height;
  t->S = S;
  t->distorted = camera.HasDistortion();
  t->fvx = S * camera.fx();
  t->fvy = S * camera.fy();
  const int W = camera.width, H = camera.height;
  if (!t->distorted) {
    t->vw = W * S;
    t->vh = H * S;
    t->cu = S * camera.u0;
    t->cv = S * camera.v0;
  } else {
    t->centre.resize(size_t(W) * H);
    t->sub.resize(size_t(W) * H * S * S);
    tbb::parallel_for(0, H, [&](int j) {
      for (int i = 0; i < W; ++i) {
        const size_t p = size_t(j) * W + i;
        t->centre[p] = camera.Unproject({i + 0.5, j + 0.5}).head<2>();
        for (int b = 0; b < S; ++b)
          for (int a = 0; a < S; ++a)
            t->sub[p * S * S + b * S + a] =
                camera.Unproject({i + (a + 0.5) / S, j + (b + 0.5) / S}).head<2>().cast<float>();
      }
    });
    Eigen::AlignedBox2f box;
    for (const auto& s : t->sub) box.extend(s);
    const double vw = (box.max().x() - box.min().x()) * t->fvx + 2;
    const double vh = (box.max().y() - box.min().y()) * t->fvy + 2;
    if (!(vw * vh < 16.0 * W * H * S * S))
      throw Error("render: the lens distortion is too strong to render (the undistorted field is huge)");
    t->vw = static_cast<int>(std::ceil(vw));
    t->vh = static_cast<int>(std::ceil(vh));
    t->cu = -box.min().x() * t->fvx + 1;
    t->cv = -box.min().y() * t->fvy + 1;
    // Each sub-sample looks at the 2x2 raster samples around it (top-left one stored) and takes the
    // nearest of their faces that contains its exact ray, so edges are placed exactly, not snapped.
    t->sub_cell.resize(t->sub.size());
    for (size_t k = 0; k < t->sub.size(); ++k) {
      const int X = static_cast<int>(std::floor(t->sub[k].x() * t->fvx + t->cu - 0.5));
      const int Y = static_cast<int>(std::floor(t->sub[k].y() * t->fvy + t->cv - 0.5));
      t->sub_cell[k] = (X >= 0 && Y >= 0 && X + 1 < t->vw && Y + 1 < t->vh) ? Y * t->vw + X : -1;
    }
  }
  std::lock_guard<std::mutex> lock(cache_mutex_);
  ray_cache_ = t;
  return t;
}

// Steps 1–2: vertices to the camera frame, then per face: cull, plane matrix, near clipping, projection to
// the visibility raster and the shading planes.
void Renderer::PrepareFaces(const RayTable& rt, const core::Pose& pose, const RenderOptions& options,
                            Scratch& sc) const {
  const Eigen::Matrix3d R = pose.R();
  const size_t nv = mesh_.vertices.size(), nf = mesh_.faces.size();
  sc.vc.resize(nv);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nv, 4096), [&](const auto& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) sc.vc[i] = R * mesh_.vertices[i] + pose.t;
  });
  sc.prims.assign(nf, Prim());
  sc.planes.resize(nf);
  sc.shade.resize(nf);
  const double near = options.near_plane;
  const Eigen::Vector3d sun = options.SunDirection();
  // A flat surface under the sun shows its albedo.
  const double light_gain =
      options.shading ? 1.0 / (options.ambient + (1 - options.ambient) * std::max(sun.z(), 0.05)) : 1.0;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, nf, 1024), [&](const auto& r) {
    for (size_t f = r.begin(); f < r.end(); ++f) {
      const io::Face& face = mesh_.faces[f];
      const Eigen::Vector3d& a = sc.vc[face.v[0]];
      const Eigen::Vector3d& b = sc.vc[face.v[1]];
      const Eigen::Vector3d& c = sc.vc[face.v[2]];
      if (a.z() < near && b.z() < near && c.z() < near) continue;
      const Eigen::Vector3d n = (b - a).cross(c - a);
      const double side = n.dot(a);  // < 0: front face (camera on the outer side of the plane)
      if (options.cull_backfaces && side >= 0) continue;
      // Edge-on faces (plane through the camera centre) cover no area.
      if (std::abs(side) <= 1e-12 * n.norm() * a.norm()) continue;
      Eigen::Matrix3d V;
      V << a, b, c;
      Eigen::Matrix3d M = V.inverse();
      if (!M.allFinite()) continue;
      // Near clipping (Sutherland–Hodgman against z = near); the plane matrix stays that of the full face.
      std::array<Eigen::Vector3d, 4> poly;
      int np = 0;
      const Eigen::Vector3d* in[3] = {&a, &b, &c};
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d& p = *in[k];
        const Eigen::Vector3d& q = *in[(k + 1) % 3];
        const bool pin = p.z() >= near, qin = q.z() >= near;
        if (pin) poly[np++] = p;
        if (pin != qin) poly[np++] = p + (q - p) * ((near - p.z()) / (q.z() - p.z()));
      }
      Prim& pr = sc.prims[f];
      double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
      for (int k = 0; k < np; ++k) {
        pr.p[k] = {rt.fvx * poly[k].x() / poly[k].z() + rt.cu, rt.fvy * poly[k].y() / poly[k].z() + rt.cv};
        xmin = std::min(xmin, pr.p[k].x());
        xmax = std::max(xmax, pr.p[k].x());
        ymin = std::min(ymin, pr.p[k].y());
        ymax = std::max(ymax, pr.p[k].y());
      }
      // Sample (I, J) has its centre at (I + 0.5, J + 0.5).
      const double x0 = std::max(std::ceil(xmin - 0.5), 0.0), x1 = std::min(std::floor(xmax - 0.5), rt.vw - 1.0);
      const double y0 = std::max(std::ceil(ymin - 0.5), 0.0), y1 = std::min(std::floor(ymax - 0.5), rt.vh - 1.0);
      if (x0 > x1 || y0 > y1) continue;
      pr.n = np;
      pr.x0 = static_cast<int>(x0);
      pr.x1 = static_cast<int>(x1);
      pr.y0 = static_cast<int>(y0);
      pr.y1 = static_cast<int>(y1);
      const Eigen::Vector3d m = M.colwise().sum().transpose();  // 1/z = m · d
      pr.A = m.x() / rt.fvx;
      pr.B = m.y() / rt.fvy;
      pr.C = m.z() - m.x() * rt.cu / rt.fvx - m.y() * rt.cv / rt.fvy;
      sc.planes[f] = M;
      sc.shade[f] = MakeShadePlane(f, M, m, side, options, sun, light_gain);
    }
  });
}

// Texture coordinates and per-vertex light of face f as planes in the ray d (see ShadePlane).
ShadePlane Renderer::MakeShadePlane(size_t f, const Eigen::Matrix3d& M, const Eigen::Vector3d& m, double side,
                                    const RenderOptions& options, const Eigen::Vector3d& sun, double light_gain) const {
  const io::Face& face = mesh_.faces[f];
  ShadePlane sp;
  sp.m = m;
  Eigen::Vector3d pu = Eigen::Vector3d::Zero(), pv = Eigen::Vector3d::Zero(), pl = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3; ++k) {
    if (face.vt[0] >= 0) {
      pu += mesh_.uvs[face.vt[k]].x() * M.row(k).transpose();
      pv += mesh_.uvs[face.vt[k]].y() * M.row(k).transpose();
    }
    double light = 1.0;
    if (options.shading) {
      Eigen::Vector3d n = face.vn[k] >= 0 ? mesh_.normals[face.vn[k]].cast<double>().normalized() : face_normals_[f];
      if (face.vn[k] < 0 && side > 0) n = -n;  // seen from behind (culling off): light the visible side
      light = (options.ambient + (1 - options.ambient) * std::max(0.0, n.dot(sun))) * light_gain;
    }
    pl += light * M.row(k).transpose();
  }
  sp.pu = pu.cast<float>();
  sp.pv = pv.cast<float>();
  sp.pl = pl.cast<float>();
  return sp;
}

// Steps 3–4: faces binned into bands of raster rows (in face order, so the result does not depend on threads),
// then the visibility raster: nearest face per sample (largest 1/z), ties keep the lower face index.
void Renderer::RasteriseVisibility(const RayTable& rt, Scratch& sc) {
  const int nbands = (rt.vh + kBandRows - 1) / kBandRows;
  sc.bins.resize(nbands);
  for (auto& b : sc.bins) b.clear();
  for (size_t f = 0; f < sc.prims.size(); ++f) {
    const Prim& p = sc.prims[f];
    if (p.n == 0) continue;
    for (int b = p.y0 / kBandRows; b <= p.y1 / kBandRows; ++b) sc.bins[b].push_back(static_cast<int>(f));
  }
  sc.wbuf.assign(size_t(rt.vw) * rt.vh, 0.0f);
  sc.ibuf.assign(size_t(rt.vw) * rt.vh, -1);
  tbb::parallel_for(0, nbands, [&](int band) {
    const int by0 = band * kBandRows, by1 = std::min(rt.vh - 1, by0 + kBandRows - 1);
    for (int f : sc.bins[band]) {
      const Prim& pr = sc.prims[f];
      for (int k = 1; k + 1 < pr.n; ++k)
        RasteriseTriangle(pr, {pr.p[0], pr.p[k], pr.p[k + 1]}, f, by0, by1, rt.vw, sc.wbuf, sc.ibuf);
    }
  });
}

// The faces seen by the S×S samples of output pixel (i, j).
void Renderer::PixelSampleFaces(const RayTable& rt, const Scratch& sc, int i, int j, int32_t* ids) {
  const int S = rt.S, SS = S * S;
  const size_t p = size_t(j) * rt.width + i;
  for (int b = 0; b < S; ++b)
    for (int a = 0; a < S; ++a) {
      int32_t id = -1;
      if (!rt.distorted) {
        id = sc.ibuf[size_t(S * j + b) * rt.vw + S * i + a];
      } else {
        const int32_t cell = rt.sub_cell[p * SS + b * S + a];
        if (cell >= 0) {
          const int32_t c4[4] = {sc.ibuf[cell], sc.ibuf[cell + 1], sc.ibuf[cell + rt.vw], sc.ibuf[cell + rt.vw + 1]};
          if (c4[0] == c4[1] && c4[0] == c4[2] && c4[0] == c4[3]) {
            id = c4[0];
          } else {
            const Eigen::Vector3d ds(rt.sub[p * SS + b * S + a].x(), rt.sub[p * SS + b * S + a].y(), 1.0);
            id = ContainingFace(sc.planes, c4, 4, ds);
            if (id < -1) id = c4[0];  // none contains the ray (sliver): keep the nearest sample's face
          }
        }
      }
      ids[b * S + a] = id;
    }
}

// The colour of face f along the exact ray d: texture filtered over the pixel footprint, times its light.
Eigen::Vector3f Renderer::ShadeRay(const ShadePlane& sp, int f, const Eigen::Vector3d& d, double inv_fx, double inv_fy,
                                   float exposure) const {
  const float s = static_cast<float>(sp.m.dot(d)), inv_s = 1.0f / s;
  const Eigen::Vector3f df = d.cast<float>();
  const io::Face& face = mesh_.faces[f];
  const int mat = face.material;
  const float light = sp.pl.dot(df) * inv_s * exposure;
  const MipTexture* tex = (mat >= 0 && face.vt[0] >= 0 && !textures_[mat].empty()) ? &textures_[mat] : nullptr;
  if (tex) {
    const float u = sp.pu.dot(df) * inv_s, v = sp.pv.dot(df) * inv_s;
    // d(u, v)/d(pixel) from u = (pu·d)/(m·d); the pixel footprint picks the mip level.
    const float mx = static_cast<float>(sp.m.x()), my = static_cast<float>(sp.m.y());
    const float kx = inv_s * static_cast<float>(inv_fx), ky = inv_s * static_cast<float>(inv_fy);
    const float dux = (sp.pu.x() - u * mx) * kx * tex->width(), dvx = (sp.pv.x() - v * mx) * kx * tex->height();
    const float duy = (sp.pu.y() - u * my) * ky * tex->width(), dvy = (sp.pv.y() - v * my) * ky * tex->height();
    const float rho2 = std::max(dux * dux + dvx * dvx, duy * duy + dvy * dvy);
    const float lod = rho2 > 1 ? 0.5f * FastLog2(rho2) : 0.0f;
    return tex->Sample(u, v, lod) * light;
  }
  if (mat >= 0) return mesh_.materials[mat].diffuse_bgr * (255.0f * light);
  return Eigen::Vector3f::Constant(200.0f * light);
}

// Step 5: colour and depth at the exact rays of every output pixel (edge pixels average their samples).
void Renderer::ShadePixels(const core::Camera& camera, const core::Pose& pose, const RayTable& rt, const Scratch& sc,
                           const RenderOptions& options, RenderResult& out) const {
  const int S = rt.S, SS = S * S, W = camera.width, H = camera.height;
  const Eigen::Matrix3d Rt = pose.R().transpose();
  const double inv_fx = 1.0 / camera.fx(), inv_fy = 1.0 / camera.fy();
  const float exposure = static_cast<float>(options.exposure);
  const float noise_sigma = static_cast<float>(options.noise_sigma);
  auto colour_of = [&](int f, const Eigen::Vector3d& d) -> Eigen::Vector3f {
    return f >= 0 ? ShadeRay(sc.shade[f], f, d, inv_fx, inv_fy, exposure) : SkyColour(Rt, d);
  };
  tbb::parallel_for(0, H, [&](int j) {
    uint8_t* img = out.image.ptr<uint8_t>(j);
    float* dep = out.depth.ptr<float>(j);
    int32_t* fid = out.face.ptr<int32_t>(j);
    std::array<int32_t, 16> ids;
    // Colours go to a float row first: byte stores would alias every value the loop reads and force
    // the compiler to reload them after each pixel.
    thread_local std::vector<float> row_colour;
    row_colour.resize(size_t(W) * 3);
    float* rc = row_colour.data();
    for (int i = 0; i < W; ++i) {
      const size_t p = size_t(j) * W + i;
      PixelSampleFaces(rt, sc, i, j, ids.data());
      const Eigen::Vector3d dc =
          rt.distorted ? Eigen::Vector3d(rt.centre[p].x(), rt.centre[p].y(), 1.0)
                       : Eigen::Vector3d((i + 0.5 - camera.u0) * inv_fx, (j + 0.5 - camera.v0) * inv_fy, 1.0);
      bool uniform = true;
      for (int k = 1; k < SS; ++k) uniform &= ids[k] == ids[0];
      Eigen::Vector3f colour;
      int centre_face = -1;
      if (uniform) {
        centre_face = ids[0];
        colour = colour_of(centre_face, dc);
      } else {
        // The face through the exact pixel centre: the nearest of the sampled faces that contains it.
        centre_face = std::max(-1, ContainingFace(sc.planes, ids.data(), SS, dc));
        colour.setZero();
        for (int b = 0; b < S; ++b)
          for (int a = 0; a < S; ++a) {
            Eigen::Vector3d ds;
            if (rt.distorted) {
              ds << rt.sub[p * SS + b * S + a].cast<double>(), 1.0;
            } else {
              ds << (i + (a + 0.5) / S - camera.u0) * inv_fx, (j + (b + 0.5) / S - camera.v0) * inv_fy, 1.0;
            }
            colour += colour_of(ids[b * S + a], ds);
          }
        colour /= static_cast<float>(SS);
      }
      fid[i] = centre_face;
      dep[i] = centre_face >= 0 ? static_cast<float>(1.0 / sc.shade[centre_face].m.dot(dc)) : 0.0f;
      rc[3 * i] = colour[0];
      rc[3 * i + 1] = colour[1];
      rc[3 * i + 2] = colour[2];
    }
    const size_t p0 = size_t(j) * W * 3;
    for (int k = 0; k < 3 * W; ++k) {
      float val = rc[k];
      if (noise_sigma > 0) val += noise_sigma * Gaussian(options.noise_seed, p0 + k);
      img[k] = static_cast<uint8_t>(std::clamp(val, 0.0f, 255.0f) + 0.5f);
    }
  });
}

RenderResult Renderer::Render(const core::Camera& camera, const core::Pose& pose, const RenderOptions& options) const {
  camera.Validate();
  options.Check();
  const auto rays = Rays(camera, options.supersample);
  thread_local Scratch scratch;
  PrepareFaces(*rays, pose, options, scratch);
  RasteriseVisibility(*rays, scratch);
  RenderResult out;
  out.image.create(camera.height, camera.width, CV_8UC3);
  out.depth.create(camera.height, camera.width, CV_32F);
  out.face.create(camera.height, camera.width, CV_32S);
  ShadePixels(camera, pose, *rays, scratch, options, out);
  return out;
}

}  // namespace fmv3d::render
