#include "fmv3d/synth/scene.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/synth/noise.h"
#include "fmv3d/synth/textures.h"

namespace fmv3d::synth {
namespace {

// Small helper to assemble meshes with outward-wound faces.
struct Builder {
  io::TexturedMesh m;
  int V(const Eigen::Vector3d& p) {
    m.vertices.push_back(p);
    return static_cast<int>(m.vertices.size()) - 1;
  }
  int T(double u, double v) {
    m.uvs.emplace_back(static_cast<float>(u), static_cast<float>(v));
    return static_cast<int>(m.uvs.size()) - 1;
  }
  // Adds triangle (a, b, c), flipped if needed so that its normal points along `outward`.
  void Tri(int a, int b, int c, int ta, int tb, int tc, int mat, const Eigen::Vector3d& outward) {
    io::Face f;
    const Eigen::Vector3d n = (m.vertices[b] - m.vertices[a]).cross(m.vertices[c] - m.vertices[a]);
    if (n.dot(outward) < 0) {
      std::swap(b, c);
      std::swap(tb, tc);
    }
    f.v[0] = a, f.v[1] = b, f.v[2] = c;
    f.vt[0] = ta, f.vt[1] = tb, f.vt[2] = tc;
    f.material = mat;
    m.faces.push_back(f);
  }
  void Quad(const int v[4], const int t[4], int mat, const Eigen::Vector3d& outward) {
    Tri(v[0], v[1], v[2], t[0], t[1], t[2], mat, outward);
    Tri(v[0], v[2], v[3], t[0], t[2], t[3], mat, outward);
  }
  int Material(const std::string& name, const Eigen::Vector3f& kd_bgr, cv::Mat texture) {
    io::Material mat;
    mat.name = name;
    mat.diffuse_bgr = kd_bgr;
    if (!texture.empty()) mat.texture_file = name + ".png";
    mat.texture = std::move(texture);
    m.materials.push_back(std::move(mat));
    return static_cast<int>(m.materials.size()) - 1;
  }
};

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Terrain grid over `extent` with `step` metres spacing, smooth normals and a single ground texture.
io::TexturedMesh MakeTerrain(const Eigen::AlignedBox2d& extent, double step,
                             const std::function<double(double, double)>& h, cv::Mat texture) {
  Builder b;
  const int mat = b.Material("ground", {0.4f, 0.6f, 0.5f}, std::move(texture));
  const int nx = static_cast<int>(std::lround(extent.sizes().x() / step)) + 1;
  const int ny = static_cast<int>(std::lround(extent.sizes().y() / step)) + 1;
  const double sx = extent.sizes().x() / (nx - 1), sy = extent.sizes().y() / (ny - 1);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = extent.min().x() + i * sx, y = extent.min().y() + j * sy;
      b.V({x, y, h(x, y)});
      b.T(static_cast<double>(i) / (nx - 1), static_cast<double>(j) / (ny - 1));
      const double e = 0.5;
      const Eigen::Vector3d n(-(h(x + e, y) - h(x - e, y)) / (2 * e), -(h(x, y + e) - h(x, y - e)) / (2 * e), 1);
      b.m.normals.push_back(n.normalized().cast<float>());
    }
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int a = j * nx + i, c = a + 1, d = a + nx, e = d + 1;
      b.Tri(a, c, e, a, c, e, mat, Eigen::Vector3d::UnitZ());
      b.Tri(a, e, d, a, e, d, mat, Eigen::Vector3d::UnitZ());
    }
  for (auto& f : b.m.faces)
    for (int k = 0; k < 3; ++k) f.vn[k] = f.v[k];
  return std::move(b.m);
}

// A coarse ring of ground from the terrain tile out to 3.5 tile widths, with a hole where the tile is. The ring
// is 0.3 m below the height function except on the tile's border, where the cells next to the tile meet it
// through the tile's own border vertices (`tile_step` apart, as MakeTerrain places them): a coarse cell's edge
// would otherwise stand up to metres off the tile's edge — a cliff no real terrain has, which every oblique
// view of the far field saw and no reconstruction could follow.
io::TexturedMesh MakeFarGround(const Eigen::AlignedBox2d& tile, double tile_step,
                               const std::function<double(double, double)>& h, double detail) {
  const double e = tile.sizes().x(), step = e / 4;
  const Eigen::Vector2d c = tile.center();
  const int n = 28;  // cells per side: 7 tile widths
  const Eigen::AlignedBox2d far(c - Eigen::Vector2d::Constant(3.5 * e), c + Eigen::Vector2d::Constant(3.5 * e));
  const int tex = std::clamp(static_cast<int>(std::lround(1024 * detail)), 64, 2048);
  cv::Mat texture = GroundTexture(tex, far, 77, nullptr, nullptr);
  // Distant land: blur away texel-level grain (texels are ~20 m here) and add a little haze.
  cv::GaussianBlur(texture, texture, cv::Size(0, 0), 1.5);
  cv::addWeighted(texture, 0.75, cv::Mat(texture.size(), texture.type(), cv::Scalar(150, 160, 150)), 0.25, 0, texture);
  Builder b;
  const int mat = b.Material("far_ground", {0.4f, 0.6f, 0.5f}, texture);
  const double tol = 1e-6 * e;
  auto on_border = [&](double x, double y) {
    const bool in_x = x > tile.min().x() - tol && x < tile.max().x() + tol;
    const bool in_y = y > tile.min().y() - tol && y < tile.max().y() + tol;
    return (in_y && (std::abs(x - tile.min().x()) < tol || std::abs(x - tile.max().x()) < tol)) ||
           (in_x && (std::abs(y - tile.min().y()) < tol || std::abs(y - tile.max().y()) < tol));
  };
  // One vertex with its texture coordinate (same index) and normal.
  auto vertex = [&](double x, double y, double z, double g) {
    const int v = b.V({x, y, z});
    b.T((x - far.min().x()) / far.sizes().x(), (y - far.min().y()) / far.sizes().y());
    const Eigen::Vector3d nn(-(h(x + g, y) - h(x - g, y)) / (2 * g), -(h(x, y + g) - h(x, y - g)) / (2 * g), 1);
    b.m.normals.push_back(nn.normalized().cast<float>());
    return v;
  };
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = far.min().x() + i * step, y = far.min().y() + j * step;
      vertex(x, y, h(x, y) - (on_border(x, y) ? 0.0 : 0.3), 0.5 * step);
    }
  const int nx_tile = static_cast<int>(std::lround(tile.sizes().x() / tile_step)) + 1;
  const int ny_tile = static_cast<int>(std::lround(tile.sizes().y() / tile_step)) + 1;
  const double sx_tile = tile.sizes().x() / (nx_tile - 1), sy_tile = tile.sizes().y() / (ny_tile - 1);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d mid = far.min() + Eigen::Vector2d((i + 0.5) * step, (j + 0.5) * step);
      if (tile.contains(mid)) continue;
      const int a = j * (n + 1) + i, bb = a + 1, d = a + n + 1, ee = d + 1;  // (x0,y0) (x1,y0) (x0,y1) (x1,y1)
      // The cell's edge on the tile's border, if any: its two corners (p from q0's side), and the far edge.
      int p0 = -1, p1 = -1, q0 = -1, q1 = -1;
      const double x0 = far.min().x() + i * step, y0 = far.min().y() + j * step;
      if (on_border(x0 + step, y0 + 0.5 * step) && mid.x() < tile.min().x()) p0 = bb, p1 = ee, q0 = a, q1 = d;
      if (on_border(x0, y0 + 0.5 * step) && mid.x() > tile.max().x()) p0 = a, p1 = d, q0 = bb, q1 = ee;
      if (on_border(x0 + 0.5 * step, y0 + step) && mid.y() < tile.min().y()) p0 = d, p1 = ee, q0 = a, q1 = bb;
      if (on_border(x0 + 0.5 * step, y0) && mid.y() > tile.max().y()) p0 = a, p1 = bb, q0 = d, q1 = ee;
      if (p0 < 0) {
        b.Tri(a, bb, ee, a, bb, ee, mat, Eigen::Vector3d::UnitZ());
        b.Tri(a, ee, d, a, ee, d, mat, Eigen::Vector3d::UnitZ());
        continue;
      }
      // The tile's border vertices along the shared edge, then a fan to the far edge's two corners.
      const Eigen::Vector3d from = b.m.vertices[p0], to = b.m.vertices[p1];
      const bool along_x = std::abs(to.x() - from.x()) > std::abs(to.y() - from.y());
      const double lo = along_x ? std::min(from.x(), to.x()) : std::min(from.y(), to.y());
      const double hi = along_x ? std::max(from.x(), to.x()) : std::max(from.y(), to.y());
      const bool forward = along_x ? to.x() > from.x() : to.y() > from.y();
      std::vector<int> p{p0};
      std::vector<double> at;  // the tile's vertex coordinates strictly inside the edge
      const int count = along_x ? nx_tile : ny_tile;
      for (int m = 0; m < count; ++m) {
        const double u = along_x ? tile.min().x() + m * sx_tile : tile.min().y() + m * sy_tile;
        if (u > lo + tol && u < hi - tol) at.push_back(u);
      }
      if (!forward) std::reverse(at.begin(), at.end());
      for (double u : at) {
        const double x = along_x ? u : from.x(), y = along_x ? from.y() : u;
        p.push_back(vertex(x, y, h(x, y), 0.5 * step));  // the ring's smooth shading, no fan streaks
      }
      p.push_back(p1);
      const size_t half = (p.size() - 1) / 2;
      for (size_t m = 0; m + 1 < p.size(); ++m) {
        const int q = m < half ? q0 : q1;
        b.Tri(p[m], p[m + 1], q, p[m], p[m + 1], q, mat, Eigen::Vector3d::UnitZ());
      }
      b.Tri(p[half], q1, q0, p[half], q1, q0, mat, Eigen::Vector3d::UnitZ());
    }
  for (auto& f : b.m.faces)
    for (int k = 0; k < 3; ++k) f.vn[k] = f.v[k];
  return std::move(b.m);
}

int TextureSize(double extent_m, double texels_per_metre, double detail) {
  return std::clamp(static_cast<int>(std::lround(extent_m * texels_per_metre * detail)), 64, 4096);
}

}  // namespace

io::TexturedMesh MakeBuilding(const BuildingSpec& s, double tpm) {
  if (!(s.width > 0 && s.depth > 0 && s.eave_height > 0 && s.ridge_height >= s.eave_height && s.sink >= 0))
    throw Error("building '" + s.name + "': dimensions must be positive and the ridge not below the eaves");
  Builder b;
  const bool pitched = s.ridge_height > s.eave_height + 1e-9;
  const double hd = s.heading_deg * M_PI / 180, ch = std::cos(hd), sh = std::sin(hd);
  auto world = [&](double x, double y, double z) {
    return Eigen::Vector3d(s.base.x() + ch * x - sh * y, s.base.y() + sh * x + ch * y, s.base.z() + z);
  };
  const double w2 = s.width / 2, d2 = s.depth / 2, zb = -s.sink, ze = s.eave_height, zr = s.ridge_height;
  const double cx[4] = {-w2, w2, w2, -w2}, cy[4] = {-d2, -d2, d2, d2};  // counter-clockwise from above
  int bot[4], eave[4];
  for (int k = 0; k < 4; ++k) bot[k] = b.V(world(cx[k], cy[k], zb));
  for (int k = 0; k < 4; ++k) eave[k] = b.V(world(cx[k], cy[k], ze));
  const double lens[4] = {s.width, s.depth, s.width, s.depth};
  const double perimeter = 2 * (s.width + s.depth), total = zr - zb;

  FacadeSpec fs;
  fs.wall_lengths = {lens[0], lens[1], lens[2], lens[3]};
  fs.total_height = total;
  fs.ground_offset = s.sink;
  fs.eave_height = s.eave_height;
  fs.floor_height = s.floor_height;
  fs.texels_per_metre = tpm;
  fs.seed = s.style_seed;
  const int facade = b.Material(s.name + "_facade", {0.7f, 0.75f, 0.8f}, tpm > 0 ? FacadeTexture(fs) : cv::Mat());
  const double slope_len = std::hypot(d2, zr - ze);
  const int roof = b.Material(
      s.name + "_roof", {0.3f, 0.3f, 0.55f},
      tpm > 0 ? RoofTexture(s.width, pitched ? 2 * slope_len : s.depth, pitched, tpm, s.style_seed + 101) : cv::Mat());
  const int base_mat = b.Material(s.name + "_base", {0.4f, 0.4f, 0.4f}, cv::Mat());
  if (tpm <= 0) {
    b.m.materials[facade].texture_file = s.name + "_facade.png";
    b.m.materials[roof].texture_file = s.name + "_roof.png";
  }
  const Eigen::Vector3d centre = world(0, 0, (zb + zr) / 2);
  auto outward = [&](const Eigen::Vector3d& p) { return Eigen::Vector3d(p - centre); };

  double u = 0;
  for (int k = 0; k < 4; ++k) {
    const int k1 = (k + 1) % 4;
    const double u0 = u / perimeter, u1 = (u + lens[k]) / perimeter, ve = (ze - zb) / total;
    const int v[4] = {bot[k], bot[k1], eave[k1], eave[k]};
    const int t[4] = {b.T(u0, 0), b.T(u1, 0), b.T(u1, ve), b.T(u0, ve)};
    Eigen::Vector3d out = world((cx[k] + cx[k1]) / 2, (cy[k] + cy[k1]) / 2, 0) - world(0, 0, 0);
    b.Quad(v, t, facade, out);
    u += lens[k];
  }
  if (pitched) {
    // Ridge along the building's x axis; gables on the short (x = ±w/2) walls 1 and 3.
    const int re = b.V(world(w2, 0, zr)), rw = b.V(world(-w2, 0, zr));
    const double ve = (ze - zb) / total;
    const double ug1 = (lens[0] + lens[1] / 2) / perimeter,
                 ug3 = (lens[0] + lens[1] + lens[2] + lens[3] / 2) / perimeter;
    b.Tri(eave[1], eave[2], re, b.T(lens[0] / perimeter, ve), b.T((lens[0] + lens[1]) / perimeter, ve), b.T(ug1, 1),
          facade, world(1, 0, 0) - world(0, 0, 0));
    b.Tri(eave[3], eave[0], rw, b.T((perimeter - lens[3]) / perimeter, ve), b.T(1.0, ve), b.T(ug3, 1), facade,
          world(-1, 0, 0) - world(0, 0, 0));
    const int south[4] = {eave[0], eave[1], re, rw};
    const int ts[4] = {b.T(0, 0), b.T(1, 0), b.T(1, 0.5), b.T(0, 0.5)};
    b.Quad(south, ts, roof, outward(world(0, -d2 / 2, (ze + zr) / 2)));
    const int north[4] = {eave[2], eave[3], rw, re};
    const int tn[4] = {b.T(1, 1), b.T(0, 1), b.T(0, 0.5), b.T(1, 0.5)};
    b.Quad(north, tn, roof, outward(world(0, d2 / 2, (ze + zr) / 2)));
  } else {
    const int t[4] = {b.T(0, 0), b.T(1, 0), b.T(1, 1), b.T(0, 1)};
    b.Quad(eave, t, roof, Eigen::Vector3d::UnitZ());
  }
  const int tb[4] = {-1, -1, -1, -1};
  b.Quad(bot, tb, base_mat, -Eigen::Vector3d::UnitZ());
  return std::move(b.m);
}

void SceneOptions::Check() const {
  if (!(detail > 0 && detail <= 4)) throw Error("scene: detail must be in (0, 4]");
  if (!(board_square > 0)) throw Error("scene: board square size must be positive");
}

const std::vector<SceneKind>& SceneKinds() {
  static const std::vector<SceneKind> kinds = {SceneKind::kBuilding, SceneKind::kTown, SceneKind::kTerrain,
                                               SceneKind::kBoard, SceneKind::kSand};
  return kinds;
}

const char* SceneName(SceneKind kind) {
  switch (kind) {
    case SceneKind::kBuilding:
      return "building";
    case SceneKind::kTown:
      return "town";
    case SceneKind::kTerrain:
      return "terrain";
    case SceneKind::kBoard:
      return "board";
    case SceneKind::kSand:
      return "sand";
  }
  return "building";
}

SceneKind ParseScene(const std::string& name) {
  for (SceneKind k : SceneKinds())
    if (name == SceneName(k)) return k;
  throw Error("unknown scene '" + name + "' (expected building, town, terrain, board or sand)");
}

namespace {

Scene MakeBoard(const SceneOptions& o) {
  Scene scene;
  scene.name = "board";
  const double sq = o.board_square;
  // 10 × 7 squares (9 × 6 inner corners at (i·sq, j·sq), i = 0..8, j = 0..5) and a one-square white margin.
  const int ppsq = 64;
  const int cols = 12 * ppsq, rows = 9 * ppsq;
  cv::Mat tex(rows, cols, CV_8UC3, cv::Scalar(235, 235, 235));
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int sx = c / ppsq - 1, sy = (rows - 1 - r) / ppsq - 1;  // square indices, y up
      if (sx >= 0 && sx < 10 && sy >= 0 && sy < 7 && ((sx + sy) % 2 == 0)) tex.at<cv::Vec3b>(r, c) = {25, 25, 25};
    }
  Builder b;
  const int mat = b.Material("board", {0.9f, 0.9f, 0.9f}, tex);
  const double x0 = -2 * sq, x1 = 10 * sq, y0 = -2 * sq, y1 = 7 * sq;
  const int v[4] = {b.V({x0, y0, 0}), b.V({x1, y0, 0}), b.V({x1, y1, 0}), b.V({x0, y1, 0})};
  const int t[4] = {b.T(0, 0), b.T(1, 0), b.T(1, 1), b.T(0, 1)};
  b.Quad(v, t, mat, Eigen::Vector3d::UnitZ());
  scene.mesh = std::move(b.m);
  scene.ground_height = [](double, double) { return 0.0; };
  scene.ground_extent = Eigen::AlignedBox2d(Eigen::Vector2d(x0, y0), Eigen::Vector2d(x1, y1));
  scene.target = {4 * sq, 2.5 * sq, 0};
  scene.interest_radius = 4 * sq;
  scene.characteristic_length = x1 - x0;
  scene.bounds = scene.mesh.Bounds();
  return scene;
}

}  // namespace

Scene MakeScene(SceneKind kind, const SceneOptions& o) {
  o.Check();
  if (kind == SceneKind::kBoard) return MakeBoard(o);
  Scene scene;
  scene.name = SceneName(kind);
  double extent = 0, step = 0, ground_tpm = 0;
  const double facade_tpm = 30 * o.detail;
  if (kind == SceneKind::kBuilding) {
    extent = 260, step = 2, ground_tpm = 13;
    scene.ground_height = [](double x, double y) {
      return 3.0 * (Fbm(x / 90, y / 90, 11, 4) - 0.5) * SmoothStep(30, 70, std::hypot(x, y));
    };
    BuildingSpec spec;  // the defaults are the shipped building
    scene.buildings.push_back(spec);
    scene.target = {0, 0, 15};
    scene.interest_radius = 20;
  } else if (kind == SceneKind::kTown) {
    extent = 480, step = 2.5, ground_tpm = 9;
    scene.ground_height = [](double x, double y) {
      const double r = std::hypot(x, y);
      return 14.0 * (Fbm(x / 160, y / 160, 21, 5) - 0.5) * (0.35 + 0.65 * SmoothStep(60, 160, r));
    };
    struct Lot {
      double x, y, w, d, eave, ridge, heading;
    };
    const Lot lots[] = {{0, 0, 20, 12, 24, 30, 0},     {-58, 38, 30, 18, 15, 15, 12}, {52, -36, 16, 16, 12, 16, -20},
                        {-46, -52, 40, 14, 9, 9, 35},  {62, 48, 12, 10, 8, 11, 70},   {4, 74, 22, 22, 42, 42, 5},
                        {-88, -6, 14, 24, 18, 23, -8}, {30, 20, 10, 8, 6, 9, 50},     {96, -8, 26, 12, 20, 20, 95},
                        {-20, -92, 18, 10, 11, 14, 15}};
    int k = 0;
    for (const Lot& l : lots) {
      BuildingSpec s;
      s.name = fmt::format("building_{}", k);
      s.width = l.w, s.depth = l.d, s.eave_height = l.eave, s.ridge_height = l.ridge, s.heading_deg = l.heading;
      const double z = scene.ground_height(l.x, l.y);
      double zmin = z;
      for (double fx : {-0.5, 0.0, 0.5})
        for (double fy : {-0.5, 0.0, 0.5}) {
          const double hd = l.heading * M_PI / 180;
          const double px = l.x + std::cos(hd) * fx * l.w - std::sin(hd) * fy * l.d;
          const double py = l.y + std::sin(hd) * fx * l.w + std::cos(hd) * fy * l.d;
          zmin = std::min(zmin, scene.ground_height(px, py));
        }
      s.base = {l.x, l.y, z};
      s.sink = z - zmin + 0.3;
      s.style_seed = 1000 + k;
      scene.buildings.push_back(s);
      ++k;
    }
    scene.target = {0, 0, scene.ground_height(0, 0) + 10};
    scene.interest_radius = 75;
  } else if (kind == SceneKind::kTerrain) {
    extent = 800, step = 4, ground_tpm = 5;
    scene.ground_height = [](double x, double y) {
      const double hills = 30.0 * Fbm(x / 220, y / 220, 31, 6);
      const double d = (0.8 * x - 0.6 * y + 40) / 70.0;  // distance to the ridge line, in widths
      const double ridge = 55.0 * std::exp(-0.5 * d * d) * (0.6 + 0.4 * RidgedFbm(x / 120, y / 120, 32, 4));
      return hills + ridge - 10.0;
    };
    scene.target = {0, 0, scene.ground_height(0, 0)};
    scene.interest_radius = 140;
  } else if (kind == SceneKind::kSand) {
    extent = 700, step = 2, ground_tpm = 6;
    scene.ground_height = [](double x, double y) {
      const double dunes = 14.0 * Fbm(x / 160, y / 160, 41, 5);
      const double crest = 0.5 + 0.5 * std::sin((0.6 * x - 0.8 * y) / 45.0 + 3.0 * Fbm(x / 300, y / 300, 42, 3));
      return dunes + 6.0 * crest * crest - 10.0;
    };
    scene.target = {0, 0, scene.ground_height(0, 0)};
    scene.interest_radius = 120;
  }
  scene.ground_extent =
      Eigen::AlignedBox2d(Eigen::Vector2d(-extent / 2, -extent / 2), Eigen::Vector2d(extent / 2, extent / 2));
  struct Apron {
    double x, y, c, s, hw, hd;
  };  // building footprints grown by 4 m: paved
  std::vector<Apron> aprons;
  for (const auto& s : scene.buildings) {
    const double hd = s.heading_deg * M_PI / 180;
    aprons.push_back({s.base.x(), s.base.y(), std::cos(hd), std::sin(hd), s.width / 2 + 4, s.depth / 2 + 4});
  }
  auto paved = [aprons](double x, double y) {
    for (const auto& a : aprons) {
      const double dx = x - a.x, dy = y - a.y;
      if (std::abs(dx) > a.hw + a.hd || std::abs(dy) > a.hw + a.hd) continue;
      if (std::abs(a.c * dx + a.s * dy) < a.hw && std::abs(-a.s * dx + a.c * dy) < a.hd) return true;
    }
    return false;
  };
  const int tex = TextureSize(extent, ground_tpm, o.detail);
  scene.mesh =
      MakeTerrain(scene.ground_extent, step, scene.ground_height,
                  kind == SceneKind::kSand ? LowTextureGround(tex, scene.ground_extent, 7)
                                           : GroundTexture(tex, scene.ground_extent, 7, scene.ground_height, paved));
  double tallest = 0;
  for (const auto& s : scene.buildings) {
    scene.mesh.Append(MakeBuilding(s, facade_tpm));
    tallest = std::max(tallest, s.ridge_height);
  }
  scene.bounds = scene.mesh.Bounds();
  if (scene.buildings.empty()) tallest = scene.bounds.max().z() - scene.bounds.min().z();
  scene.characteristic_length = tallest;
  scene.mesh.Append(MakeFarGround(scene.ground_extent, step, scene.ground_height, o.detail));
  return scene;
}

}  // namespace fmv3d::synth
