// The point octree (pipeline/point_octree.h) and the tiles stage (pipeline/tiles_stage.h): every point in
// exactly one tile, tile budgets, uniform interior subsamples, and a tileset that parses back.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <random>
#include <set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/io/tiles3d.h"
#include "fmv3d/pipeline/point_octree.h"
#include "fmv3d/pipeline/tiles_stage.h"
#include "test_util.h"

namespace fmv3d::pipeline {
namespace {

namespace fs = std::filesystem;

// A terrain-like surface: z = f(x, y) over 100 x 60 m, with colours encoding the point's index.
std::vector<TilePoint> Surface(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<TilePoint> pts(n);
  for (size_t i = 0; i < n; ++i) {
    const float x = 100 * u(rng), y = 60 * u(rng);
    pts[i].position = {x, y, 5 * std::sin(x / 10) + 2 * std::cos(y / 7)};
    pts[i].normal = {0, 0, 1};
    pts[i].rgb[0] = i & 255, pts[i].rgb[1] = (i >> 8) & 255, pts[i].rgb[2] = (i >> 16) & 255;
  }
  return pts;
}

uint32_t IdOf(const uint8_t* rgb) { return rgb[0] | (rgb[1] << 8) | (rgb[2] << 16); }

TEST(PointOctree, EveryPointOnceAndBudgetsHeld) {
  const size_t n = 200000;
  OctreeOptions o;
  o.max_points_per_tile = 5000;
  const PointOctree tree = BuildPointOctree(Surface(n, 3), o);
  ASSERT_EQ(tree.points.size(), n);
  ASSERT_GT(tree.nodes.size(), 9u);
  std::vector<int> seen(n, 0);
  size_t total = 0;
  int max_level = 0;
  for (const auto& node : tree.nodes) {
    EXPECT_LE(node.count, o.max_points_per_tile) << node.name;
    EXPECT_GT(node.count, 0u) << node.name;
    total += node.count;
    max_level = std::max(max_level, node.level);
    for (size_t i = node.begin; i < node.begin + node.count; ++i) {
      ++seen[IdOf(tree.points[i].rgb)];
      EXPECT_TRUE(node.cell.contains(tree.points[i].position)) << node.name;
      EXPECT_TRUE(node.bounds.contains(tree.points[i].position)) << node.name;
    }
    // Children tile the rest of the subtree contiguously.
    size_t next = node.begin + node.count;
    for (int c : node.children) {
      EXPECT_EQ(tree.nodes[c].begin, next);
      EXPECT_EQ(tree.nodes[c].level, node.level + 1);
      EXPECT_TRUE(node.cell.contains(tree.nodes[c].cell));
      next = tree.nodes[c].subtree_end;
    }
    EXPECT_EQ(next, node.subtree_end);
  }
  EXPECT_EQ(total, n);
  for (size_t i = 0; i < n; ++i) ASSERT_EQ(seen[i], 1) << "point " << i;
  EXPECT_GE(max_level, 2);
}

TEST(PointOctree, RootSubsampleCoversTheWholeCloud) {
  OctreeOptions o;
  o.max_points_per_tile = 4000;
  const PointOctree tree = BuildPointOctree(Surface(100000, 5), o);
  const OctreeNode& root = tree.nodes[0];
  EXPECT_GT(root.count, o.max_points_per_tile / 4);  // not a token sample
  // Every 10 x 10 m block of the 100 x 60 m surface has root points: a coarse picture of everything.
  std::set<std::pair<int, int>> blocks;
  for (size_t i = root.begin; i < root.begin + root.count; ++i)
    blocks.insert(
        {static_cast<int>(tree.points[i].position.x() / 10), static_cast<int>(tree.points[i].position.y() / 10)});
  EXPECT_EQ(blocks.size(), 60u);
}

TEST(PointOctree, SmallAndDegenerateClouds) {
  EXPECT_TRUE(BuildPointOctree({}, {}).nodes.empty());
  std::vector<TilePoint> same(1000);
  for (auto& p : same) p.position = {1, 2, 3};
  OctreeOptions o;
  o.max_points_per_tile = 64;
  o.max_depth = 4;
  const PointOctree tree = BuildPointOctree(same, o);  // all at one spot: stops at max_depth, keeps every point
  size_t total = 0;
  for (const auto& node : tree.nodes) total += node.count;
  EXPECT_EQ(total, 1000u);
  std::vector<TilePoint> with_nan(3);
  with_nan[1].position.x() = std::nanf("");
  EXPECT_EQ(BuildPointOctree(with_nan, {}).points.size(), 2u);
  o.max_points_per_tile = 10;
  EXPECT_THROW(BuildPointOctree(same, o), Error);
}

// Walks tileset JSON, parsing every .pnts it names and collecting the point ids.
void Collect(const nlohmann::json& tile, const fs::path& dir, double parent_error, std::vector<int>* seen, int* tiles,
             int* tiles_with_views = nullptr) {
  EXPECT_LE(tile["geometricError"].get<double>(), parent_error);
  ASSERT_TRUE(tile["boundingVolume"].contains("box"));
  EXPECT_EQ(tile["boundingVolume"]["box"].size(), 12u);
  if (tile.contains("content")) {
    const std::string uri = tile["content"]["uri"];
    if (uri.size() > 5 && uri.substr(uri.size() - 5) == ".pnts") {
      const io::PntsTile t = io::DecodePnts(core::ReadTextFile(dir / uri));
      ++*tiles;
      const auto& b = tile["boundingVolume"]["box"];
      const bool has_views = !t.views.empty();
      if (tiles_with_views && has_views) ++*tiles_with_views;
      for (size_t i = 0; i < t.positions.size(); ++i) {
        ++(*seen)[IdOf(t.colors[i].data())];
        if (has_views) EXPECT_EQ(t.views[i], 2 + IdOf(t.colors[i].data()) % 5);
        if (!t.sigma.empty()) EXPECT_EQ(t.sigma[i], 0.001f * (1 + IdOf(t.colors[i].data()) % 7));
        const Eigen::Vector3d p = t.rtc_center + t.positions[i].cast<double>();
        for (int k = 0; k < 3; ++k) EXPECT_LE(std::abs(p[k] - b[k].get<double>()), b[3 + 4 * k].get<double>() + 1e-3);
      }
    }
  }
  if (tile.contains("children"))
    for (const auto& c : tile["children"])
      Collect(c, dir, tile["geometricError"].get<double>(), seen, tiles, tiles_with_views);
}

TEST(TilesStage, WritesAParseableTilesetWithEveryPointOnce) {
  test::TempDir ws("tiles");
  const std::vector<TilePoint> pts = Surface(60000, 7);
  io::OrientedPointCloud cloud;
  for (const auto& p : pts) {
    cloud.positions.push_back(p.position.cast<double>());
    cloud.normals.push_back(p.normal);
    cloud.colors.emplace_back(p.rgb[0], p.rgb[1], p.rgb[2]);
    cloud.visibility.push_back(std::vector<uint32_t>(2 + IdOf(p.rgb) % 5, 1));  // 2-6 views
    cloud.sigma.push_back(0.001f * (1 + IdOf(p.rgb) % 7));
  }
  fs::create_directories(ws / "dense");
  io::WritePointCloudPly(cloud, ws / "dense" / "fused.ply");
  TilesOptions o;
  o.octree.max_points_per_tile = 4000;
  const nlohmann::json summary = RunTilesStage(ws.path(), o);
  EXPECT_EQ(summary["points"], 60000);
  EXPECT_FALSE(summary["georeferenced"].get<bool>());
  const nlohmann::json tileset = core::ReadJson(ws / "tiles" / "tileset.json");
  EXPECT_EQ(tileset["asset"]["version"], "1.0");
  EXPECT_FALSE(tileset["root"].contains("transform"));
  std::vector<int> seen(60000, 0);
  int tiles = 0, with_views = 0;
  Collect(tileset["root"], ws / "tiles", tileset["geometricError"].get<double>(), &seen, &tiles, &with_views);
  EXPECT_EQ(tiles, summary["tiles"].get<int>());
  EXPECT_EQ(with_views, tiles);  // fused.ply's visibility lists became every tile's "views"
  // ... and its σ every tile's "sigma" (checked per point in Collect).
  EXPECT_FALSE(io::DecodePnts(core::ReadTextFile(ws / "tiles" / "points" / "0.pnts")).sigma.empty());
  for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i], 1) << "point " << i;
  EXPECT_FALSE(fs::exists(ws / "tiles.tmp"));
}

TEST(TilesStage, GeoreferencedWorkspaceGetsAnEcefRootTransform) {
  test::TempDir ws("tiles-geo");
  io::OrientedPointCloud cloud;
  for (int i = 0; i < 500; ++i) cloud.positions.emplace_back(i % 10, i / 10, 0.1 * i);
  fs::create_directories(ws / "dense");
  fs::create_directories(ws / "geo");
  io::WritePointCloudPly(cloud, ws / "dense" / "fused.ply");
  // sparse → ENU: scale 2, a quarter turn about z, then a shift.
  const nlohmann::json sim = {{0, -2, 0, 10}, {2, 0, 0, 20}, {0, 0, 2, 30}, {0, 0, 0, 1}};
  core::WriteJson(ws / "geo" / "georef.json", {{"origin", {{"lat", 46.5}, {"lon", 7.25}, {"alt", 800}}},
                                               {"vertical_datum", "WGS84 ellipsoid"},
                                               {"similarity", {{"matrix", sim}}}});
  const nlohmann::json summary = RunTilesStage(ws.path(), {});
  EXPECT_TRUE(summary["georeferenced"].get<bool>());
  const nlohmann::json t = core::ReadJson(ws / "tiles" / "tileset.json")["root"]["transform"];
  ASSERT_EQ(t.size(), 16u);
  Eigen::Matrix4d S;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) S(r, c) = sim[r][c].get<double>();
  const Eigen::Matrix4d expected = EnuToEcef(46.5, 7.25, 800) * S;
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) EXPECT_NEAR(t[c * 4 + r].get<double>(), expected(r, c), 1e-6) << r << "," << c;
  // The model point (1, 0, 0) lands 2 m north of the ENU point (10, 20, 30).
  const Eigen::Vector4d p = expected * Eigen::Vector4d(1, 0, 0, 1);
  const Eigen::Vector4d q = EnuToEcef(46.5, 7.25, 800) * Eigen::Vector4d(10, 22, 30, 1);
  EXPECT_NEAR((p - q).norm(), 0, 1e-6);
}

TEST(TilesStage, GeoreferencedRootTransformMapsToEcef) {
  // ENU at (0 N, 0 E, 0 m) has east = +Y, north = +Z, up = +X of ECEF, its origin at (a, 0, 0).
  const Eigen::Matrix4d M = EnuToEcef(0, 0, 0);
  EXPECT_NEAR((M * Eigen::Vector4d(0, 0, 0, 1) - Eigen::Vector4d(6378137, 0, 0, 1)).norm(), 0, 1e-6);
  EXPECT_NEAR((M * Eigen::Vector4d(1, 0, 0, 1) - Eigen::Vector4d(6378137, 1, 0, 1)).norm(), 0, 1e-6);
  EXPECT_NEAR((M * Eigen::Vector4d(0, 1, 0, 1) - Eigen::Vector4d(6378137, 0, 1, 1)).norm(), 0, 1e-6);
  EXPECT_NEAR((M * Eigen::Vector4d(0, 0, 1, 1) - Eigen::Vector4d(6378138, 0, 0, 1)).norm(), 0, 1e-6);
  // At the pole, up is +Z and the origin is at the polar radius.
  EXPECT_NEAR(EnuToEcef(90, 0, 0)(2, 3), 6356752.314, 1e-3);
}

}  // namespace
}  // namespace fmv3d::pipeline
