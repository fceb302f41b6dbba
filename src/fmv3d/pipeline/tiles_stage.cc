#include "fmv3d/pipeline/tiles_stage.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <functional>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/georef_pairs.h"
#include "fmv3d/io/ply_stream.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/io/tiles3d.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

namespace {
double GeometricError(const PointOctree& tree, const OctreeNode& node, size_t budget) {
  if (node.children.empty()) return 0;
  return 2.0 * node.cell.sizes().maxCoeff() / std::sqrt(static_cast<double>(budget));
}

Eigen::AlignedBox3d ToDouble(const Eigen::AlignedBox3f& b) { return {b.min().cast<double>(), b.max().cast<double>()}; }
}  // namespace

nlohmann::json WritePointTiles(const PointOctree& tree, const fs::path& dir) {
  if (tree.nodes.empty()) return nullptr;
  core::EnsureDirectory(dir / "points");
  size_t budget = 0;
  for (const auto& n : tree.nodes) budget = std::max(budget, n.count);
  core::Progress progress("tiles", tree.nodes.size());
  std::function<nlohmann::json(int)> write = [&](int id) -> nlohmann::json {
    const OctreeNode& node = tree.nodes[id];
    io::PntsTile tile;
    tile.rtc_center = ToDouble(node.bounds).center();
    const Eigen::Vector3f rtc = tile.rtc_center.cast<float>();
    tile.positions.reserve(node.count);
    tile.colors.reserve(node.count);
    bool normals = false, views = false, sigma = false;
    for (size_t i = node.begin; i < node.begin + node.count; ++i) {
      normals = normals || !tree.points[i].normal.isZero();
      views = views || tree.points[i].views > 0;
      sigma = sigma || tree.points[i].sigma > 0;
    }
    for (size_t i = node.begin; i < node.begin + node.count; ++i) {
      const TilePoint& p = tree.points[i];
      tile.positions.push_back(p.position - rtc);
      tile.colors.emplace_back(p.rgb[0], p.rgb[1], p.rgb[2]);
      if (normals) tile.normals.push_back(p.normal);
      if (views) tile.views.push_back(p.views);
      if (sigma) tile.sigma.push_back(p.sigma);
    }
    const std::string uri = "points/" + node.name + ".pnts";
    core::WriteTextFile(dir / uri, io::EncodePnts(tile));
    progress.Add();
    nlohmann::json j = {{"boundingVolume", io::BoxVolume(ToDouble(node.bounds))},
                        {"geometricError", GeometricError(tree, node, budget)},
                        {"refine", "ADD"},
                        {"content", {{"uri", uri}}}};
    for (int c : node.children) j["children"].push_back(write(c));
    return j;
  };
  return write(0);
}

Eigen::Matrix4d EnuToEcef(double lat_deg, double lon_deg, double h) {
  const double a = 6378137.0, f = 1 / 298.257223563, e2 = f * (2 - f);
  const double lat = lat_deg * M_PI / 180, lon = lon_deg * M_PI / 180;
  const double sl = std::sin(lat), cl = std::cos(lat), so = std::sin(lon), co = std::cos(lon);
  const double N = a / std::sqrt(1 - e2 * sl * sl);
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  M.block<3, 1>(0, 0) << -so, co, 0;              // east
  M.block<3, 1>(0, 1) << -sl * co, -sl * so, cl;  // north
  M.block<3, 1>(0, 2) << cl * co, cl * so, sl;    // up
  M.block<3, 1>(0, 3) << (N + h) * cl * co, (N + h) * cl * so, (N * (1 - e2) + h) * sl;
  return M;
}

namespace {
// The model → ECEF transform of a georeferenced workspace (null otherwise).
nlohmann::json RootTransform(const core::Workspace& ws) {
  const fs::path path = ws.georef_json();
  if (!fs::exists(path)) return nullptr;
  const nlohmann::json g = core::ReadJson(path);
  try {
    Eigen::Matrix4d sim;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) sim(r, c) = g.at("similarity").at("matrix").at(r).at(c).get<double>();
    const double lat = g.at("origin").at("lat").get<double>(), lon = g.at("origin").at("lon").get<double>();
    double h = g.at("origin").at("alt").get<double>();
    if (geo::ParseVerticalDatum(g.value("vertical_datum", std::string())) == geo::VerticalDatum::kMsl)
      if (const auto n = geo::GeoidUndulation(lat, lon)) h += *n;
    const Eigen::Matrix4d M = EnuToEcef(lat, lon, h) * sim;
    nlohmann::json t = nlohmann::json::array();
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) t.push_back(M(r, c));  // column-major, as 3D Tiles wants
    return t;
  } catch (const nlohmann::json::exception& e) {
    throw Error(path.string() + ": malformed (" + e.what() + ")");
  }
}
}  // namespace

nlohmann::json RunTilesStage(const core::Workspace& ws, const TilesOptions& options) {
  options.octree.Check();
  const auto t0 = std::chrono::steady_clock::now();
  const fs::path fused = ws.dense_dir() / "fused.ply";
  ws.Require(fused, "dense");
  // Streamed straight into the compact tile points (32 bytes each) when the PLY allows; else read whole.
  std::vector<TilePoint> points;
  const bool streamed = io::StreamPlyVertices(
      fused, [&points](size_t n) { points.reserve(n); },
      [&points](const io::PlyVertex& v) {
        TilePoint p;
        p.position = v.position;
        p.normal = v.normal;
        std::copy(v.rgb, v.rgb + 3, p.rgb);
        p.views = v.views;
        p.sigma = v.sigma;
        points.push_back(p);
      });
  if (!streamed) {
    const io::OrientedPointCloud cloud = io::ReadPointCloudPly(fused);
    points.resize(cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) {
      points[i].position = cloud.positions[i].cast<float>();
      points[i].normal = cloud.has_normals() ? cloud.normals[i] : Eigen::Vector3f::Zero();
      if (cloud.has_colors()) std::copy(cloud.colors[i].data(), cloud.colors[i].data() + 3, points[i].rgb);
      if (cloud.has_visibility())
        points[i].views = static_cast<uint8_t>(std::min<size_t>(cloud.visibility[i].size(), 255));
      if (cloud.has_sigma()) points[i].sigma = cloud.sigma[i];
    }
  }
  if (points.empty()) throw Error(fused.string() + ": no points to tile");
  const PointOctree tree = BuildPointOctree(std::move(points), options.octree);
  const fs::path out = ws.root() / "tiles", tmp = ws.root() / "tiles.tmp";
  fs::remove_all(tmp);
  core::EnsureDirectory(tmp);
  nlohmann::json children = nlohmann::json::array();
  children.push_back(WritePointTiles(tree, tmp));
  Eigen::AlignedBox3d all = ToDouble(tree.nodes[0].bounds);
  double root_error = 2 * tree.nodes[0].cell.sizes().maxCoeff();
  bool mesh = false;
  if (fs::exists(ws.mesh_dir() / "model.glb")) {
    const std::string glb = core::ReadTextFile(ws.mesh_dir() / "model.glb");
    const Eigen::AlignedBox3d box = io::GlbBoundsZUp(glb);
    core::EnsureDirectory(tmp / "mesh");
    core::WriteTextFile(tmp / "mesh" / "model.b3dm", io::EncodeB3dm(glb));
    children.push_back(
        {{"boundingVolume", io::BoxVolume(box)}, {"geometricError", 0}, {"content", {{"uri", "mesh/model.b3dm"}}}});
    all.extend(box);
    mesh = true;
  }
  nlohmann::json root = {{"boundingVolume", io::BoxVolume(all)},
                         {"geometricError", root_error},
                         {"refine", "ADD"},
                         {"children", children}};
  const nlohmann::json transform = RootTransform(ws);
  if (!transform.is_null()) root["transform"] = transform;
  core::WriteJson(tmp / "tileset.json", {{"asset", {{"version", "1.0"}, {"generator", "fmv3d " FMV3D_VERSION}}},
                                         {"geometricError", root_error},
                                         {"root", root}});
  fs::remove_all(out);
  fs::rename(tmp, out);
  int levels = 0;
  for (const auto& n : tree.nodes) levels = std::max(levels, n.level + 1);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::info("tiles: {} points in {} tiles over {} levels{}{}, {:.1f} s", tree.points.size(), tree.nodes.size(),
               levels, mesh ? " + the mesh" : "", transform.is_null() ? "" : ", georeferenced (ECEF)", seconds);
  return {{"points", tree.points.size()},          {"tiles", tree.nodes.size()}, {"levels", levels}, {"mesh", mesh},
          {"georeferenced", !transform.is_null()}, {"seconds", seconds}};
}

}  // namespace fmv3d::pipeline
