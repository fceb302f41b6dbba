#include "fmv3d/geo/dsm.h"

#include <fmt/format.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unordered_set>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/core/stats.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/las.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/texture.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

void DsmOptions::Check() const {
  if (gsd && !(*gsd > 0 && *gsd < 1e4)) throw Error("dsm: --gsd must be a positive number of metres");
  if (!(max_cells >= 1e4)) throw Error("dsm: max_cells must be at least 10000");
}

namespace {

void ToUtm(const Georef& g, std::vector<Eigen::Vector3d>* pts) {
  for (auto& p : *pts) p = g.sparse_to_enu.Apply(p);
  const LocalFrame frame(g.origin, g.utm);
  frame.EnuToUtm(pts);
}

// Points of the densest cloud available (dense, else sparse), in the sparse frame.
io::OrientedPointCloud LoadPoints(const core::Workspace& ws, std::string* source) {
  const fs::path dense = ws.dense_dir() / "fused.ply";
  if (fs::exists(dense)) {
    *source = dense.string();
    return io::ReadPointCloudPly(dense);
  }
  const fs::path sparse = ws.sparse_dir();
  if (!fs::exists(sparse / "points3D.txt"))
    throw Error(ws.name() +
                ": no surface to map (mesh/poisson.ply, dense/fused.ply or sparse/) — run the "
                "reconstruction first");
  *source = sparse.string();
  const core::Reconstruction rec = io::ReadColmapText(sparse);
  io::OrientedPointCloud cloud;
  for (const auto& [id, p] : rec.points) {
    cloud.positions.push_back(p.xyz);
    cloud.colors.push_back(p.rgb);
  }
  return cloud;
}

}  // namespace

UtmSurface LoadUtmSurface(const core::Workspace& ws, const Georef& g) {
  UtmSurface s;
  const fs::path poisson = ws.mesh_dir() / "poisson.ply";
  if (fs::exists(poisson)) {
    open3d::geometry::TriangleMesh mesh;
    if (!open3d::io::ReadTriangleMesh(poisson.string(), mesh) || mesh.triangles_.empty())
      throw Error(poisson.string() + ": cannot read a triangle mesh from it");
    s.source = poisson.string();
    s.vertices = mesh.vertices_;
    for (const auto& t : mesh.triangles_) {
      if ((t.array() < 0).any() || (t.array() >= static_cast<int>(s.vertices.size())).any())
        throw Error(poisson.string() + ": a face refers to a missing vertex");
      s.triangles.push_back(t);
    }
    if (mesh.HasVertexColors())
      for (const auto& c : mesh.vertex_colors_)
        s.colors.emplace_back(static_cast<uint8_t>(std::clamp(c.x() * 255, 0.0, 255.0)),
                              static_cast<uint8_t>(std::clamp(c.y() * 255, 0.0, 255.0)),
                              static_cast<uint8_t>(std::clamp(c.z() * 255, 0.0, 255.0)));
  } else {
    io::OrientedPointCloud cloud = LoadPoints(ws, &s.source);
    s.vertices = std::move(cloud.positions);
    s.colors = std::move(cloud.colors);
  }
  if (s.vertices.empty()) throw Error(s.source + ": the surface has no points");
  ToUtm(g, &s.vertices);
  return s;
}

double ChooseGsd(const UtmSurface& s) {
  if (!s.triangles.empty()) {
    std::vector<double> len;
    len.reserve(s.triangles.size());
    for (const auto& t : s.triangles)
      for (int k = 0; k < 3; ++k) {
        const double l = (s.vertices[t[k]] - s.vertices[t[(k + 1) % 3]]).head<2>().norm();
        if (l > 0) len.push_back(l);
      }
    if (!len.empty()) return std::max(0.01, core::Median(std::move(len)));
  }
  // Mean spacing over the occupied area: count the cells occupied at a first-guess size, then refine once.
  Eigen::Vector2d lo = s.vertices.front().head<2>(), hi = lo;
  for (const auto& p : s.vertices) lo = lo.cwiseMin(p.head<2>()), hi = hi.cwiseMax(p.head<2>());
  const double n = static_cast<double>(s.vertices.size());
  double g = std::max(0.01, std::sqrt(std::max(1e-4, (hi - lo).prod()) / n));
  for (int round = 0; round < 2; ++round) {
    std::unordered_set<int64_t> occupied;
    for (const auto& p : s.vertices) {
      const int64_t cx = static_cast<int64_t>((p.x() - lo.x()) / (4 * g)),
                    cy = static_cast<int64_t>((p.y() - lo.y()) / (4 * g));
      occupied.insert(cx * 4000003 + cy);
    }
    const double area = occupied.size() * 16 * g * g;
    g = std::max(0.01, std::sqrt(area / n));
  }
  return std::sqrt(2.0) * g;
}

cv::Mat RasteriseDsm(const UtmSurface& s, const GridSpec& grid) {
  cv::Mat h(grid.height, grid.width, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  auto cell_of = [&](const Eigen::Vector3d& p, int* r, int* c) {
    const double fc = std::floor(grid.Col(p.x())), fr = std::floor(grid.Row(p.y()));
    if (!(fr >= 0 && fc >= 0 && fr < grid.height && fc < grid.width)) return false;
    *r = static_cast<int>(fr), *c = static_cast<int>(fc);
    return true;
  };
  if (s.triangles.empty()) {
    // Points: the median height of the points in each cell. Points carry noise, and the maximum of a few
    // noisy samples of one surface sits above it (by ~1σ for a handful); the median does not.
    std::vector<std::pair<int64_t, float>> cells;
    cells.reserve(s.vertices.size());
    for (const auto& p : s.vertices) {
      int r, c;
      if (cell_of(p, &r, &c)) cells.emplace_back(static_cast<int64_t>(r) * grid.width + c, static_cast<float>(p.z()));
    }
    std::sort(cells.begin(), cells.end());
    for (size_t i = 0; i < cells.size();) {
      size_t j = i;
      while (j < cells.size() && cells[j].first == cells[i].first) ++j;
      const size_t m = i + (j - i) / 2;
      const float med = (j - i) % 2 ? cells[m].second : 0.5f * (cells[m - 1].second + cells[m].second);
      h.at<float>(static_cast<int>(cells[i].first / grid.width), static_cast<int>(cells[i].first % grid.width)) = med;
      i = j;
    }
    return h;
  }
  auto put = [&](int r, int c, double z) {
    float& v = h.at<float>(r, c);
    if (!(v >= z)) v = static_cast<float>(z);  // NaN compares false: first value wins
  };
  for (const auto& p : s.vertices) {
    int r, c;
    if (cell_of(p, &r, &c)) put(r, c, p.z());
  }
  for (const auto& t : s.triangles)
    RasteriseTriangle(grid, s.vertices[t[0]], s.vertices[t[1]], s.vertices[t[2]],
                      [&](int r, int c, const Eigen::Vector3d&, double z) { put(r, c, z); });
  return h;
}

cv::Mat CheckMeshHeights(const cv::Mat& mesh_h, const std::vector<Eigen::Vector3d>& points,
                         const std::vector<float>& sigma, const GridSpec& grid, const MeshCheckOptions& o,
                         MeshCheckStats* stats) {
  if (o.window < 0 || o.min_points < 1 || o.min_points_near < 1)
    throw Error("dsm: mesh check needs window >= 0, min_points >= 1 and min_points_near >= 1");
  if (!sigma.empty() && sigma.size() != points.size()) throw Error("dsm: one sigma per point expected");
  *stats = {};
  // Point indices sorted by cell (row * width + col); first[cell] .. first[cell + 1] are that cell's.
  std::vector<std::pair<int64_t, size_t>> binned;
  binned.reserve(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const double fc = std::floor(grid.Col(points[i].x())), fr = std::floor(grid.Row(points[i].y()));
    if (fr >= 0 && fc >= 0 && fr < grid.height && fc < grid.width)
      binned.emplace_back(static_cast<int64_t>(fr) * grid.width + static_cast<int64_t>(fc), i);
  }
  std::sort(binned.begin(), binned.end());
  std::vector<size_t> first(static_cast<size_t>(grid.width) * grid.height + 1, 0);
  for (const auto& [cell, i] : binned) ++first[cell + 1];
  for (size_t k = 1; k < first.size(); ++k) first[k] += first[k - 1];

  // Points per cell summed over rectangles (an integral image) for the gap test.
  cv::Mat count(grid.height, grid.width, CV_64F, cv::Scalar(0)), sums;
  for (int r = 0; r < grid.height; ++r)
    for (int c = 0; c < grid.width; ++c) {
      const size_t cell = static_cast<size_t>(r) * grid.width + c;
      count.at<double>(r, c) = static_cast<double>(first[cell + 1] - first[cell]);
    }
  cv::integral(count, sums, CV_64F);
  auto points_within = [&](int r, int c, int w) {
    const int r0 = std::max(0, r - w), r1 = std::min(grid.height, r + w + 1);
    const int c0 = std::max(0, c - w), c1 = std::min(grid.width, c + w + 1);
    return sums.at<double>(r1, c1) - sums.at<double>(r0, c1) - sums.at<double>(r1, c0) + sums.at<double>(r0, c0);
  };

  cv::Mat out = mesh_h.clone();
  std::vector<double> hs, ss;
  // The heights (and stated σ) of the points within w cells of (r, c), into hs and ss.
  auto gather = [&](int r, int c, int w) {
    hs.clear(), ss.clear();
    for (int rr = std::max(0, r - w); rr <= std::min(grid.height - 1, r + w); ++rr)
      for (int cc = std::max(0, c - w); cc <= std::min(grid.width - 1, c + w); ++cc) {
        const size_t cell = static_cast<size_t>(rr) * grid.width + cc;
        for (size_t k = first[cell]; k < first[cell + 1]; ++k) {
          hs.push_back(points[binned[k].second].z());
          if (!sigma.empty()) ss.push_back(sigma[binned[k].second]);
        }
      }
  };
  for (int r = 0; r < mesh_h.rows; ++r)
    for (int c = 0; c < mesh_h.cols; ++c) {
      const float m = mesh_h.at<float>(r, c);
      if (!std::isfinite(m)) continue;
      if (o.max_gap >= 0 && points_within(r, c, o.max_gap) == 0) {
        out.at<float>(r, c) = std::numeric_limits<float>::quiet_NaN();
        ++stats->unmeasured;
        continue;
      }
      gather(r, c, o.window);
      if (hs.size() < o.min_points) {
        // Few points under the cell: the mesh is still overruled where it stands above every point near it.
        if (o.max_gap <= o.window) continue;
        gather(r, c, o.max_gap);
        if (hs.size() < o.min_points_near) continue;
        ++stats->checked;
        const double tol = std::max(grid.gsd, ss.empty() ? 0.0 : core::Median(ss));
        if (m > *std::max_element(hs.begin(), hs.end()) + tol) {
          ++stats->replaced_above;
          out.at<float>(r, c) = static_cast<float>(core::Median(hs));
        }
        continue;
      }
      ++stats->checked;
      const double q25 = core::Quantile(hs, 0.25), q75 = core::Quantile(hs, 0.75);
      const double tol = std::max(grid.gsd, ss.empty() ? 0.0 : core::Median(ss));
      if (m > q75 + tol || m < q25 - tol) {
        ++(m > q75 + tol ? stats->replaced_above : stats->replaced_below);
        out.at<float>(r, c) = static_cast<float>(core::Median(hs));
      }
    }
  return out;
}

nlohmann::json RunDsmStage(const core::Workspace& ws, const DsmOptions& o) {
  o.Check();
  const Georef g = ReadGeoref(ws);
  const UtmSurface s = LoadUtmSurface(ws, g);
  double gsd = o.gsd ? *o.gsd : ChooseGsd(s);
  // Extent: the 0.2-99.8% quantiles widened by 5% (never past the data), so a few stray points far away
  // (sparse outliers) neither blow up the grid nor coarsen its cells; they are left out.
  Eigen::Vector2d lo, hi;
  for (int k = 0; k < 2; ++k) {
    std::vector<double> v;
    v.reserve(s.vertices.size());
    for (const auto& p : s.vertices) v.push_back(p[k]);
    std::sort(v.begin(), v.end());
    const double a = v[static_cast<size_t>(0.002 * (v.size() - 1))], b = v[static_cast<size_t>(0.998 * (v.size() - 1))];
    lo[k] = std::max(v.front(), a - 0.05 * (b - a));
    hi[k] = std::min(v.back(), b + 0.05 * (b - a));
  }
  GridSpec grid = GridSpec::Covering(lo, hi, gsd, g.utm);
  if (static_cast<double>(grid.width) * grid.height > o.max_cells) {
    const double f = std::sqrt(static_cast<double>(grid.width) * grid.height / o.max_cells);
    spdlog::warn("dsm: {:.3f} m cells would make a {}x{} grid; using {:.3f} m", gsd, grid.width, grid.height, gsd * f);
    gsd *= f * 1.01;
    grid = GridSpec::Covering(lo, hi, gsd, g.utm);
  }
  spdlog::info("dsm: {} ({} {}), {}x{} cells of {:.3f} m", s.source, s.vertices.size(),
               s.triangles.empty() ? "points" : fmt::format("vertices, {} triangles", s.triangles.size()), grid.width,
               grid.height, gsd);
  cv::Mat h = RasteriseDsm(s, grid);
  // The points: what a mesh is checked against, and the LAS (points, not mesh vertices: dense, else sparse).
  UtmSurface pts;
  MeshCheckStats mesh_check;
  bool checked = false;
  if (s.triangles.empty()) {
    pts = s;
  } else {
    io::OrientedPointCloud cloud = LoadPoints(ws, &pts.source);
    pts.vertices = std::move(cloud.positions);
    pts.colors = std::move(cloud.colors);
    ToUtm(g, &pts.vertices);
    std::vector<float> sigma_m = std::move(cloud.sigma);
    for (float& v : sigma_m) v = static_cast<float>(v * g.sparse_to_enu.s);
    // Only the dense cloud the mesh was made from can judge it: sparse points are too far apart.
    checked = pts.source == (ws.dense_dir() / "fused.ply").string();
    if (checked) {
      h = CheckMeshHeights(h, pts.vertices, sigma_m, grid, {}, &mesh_check);
      spdlog::info(
          "dsm: mesh checked against {} points in {} cells: {} above and {} below what they allow, replaced; {} "
          "with no point within {} cells left without data",
          pts.vertices.size(), mesh_check.checked, mesh_check.replaced_above, mesh_check.replaced_below,
          mesh_check.unmeasured, MeshCheckOptions{}.max_gap);
    }
  }
  const fs::path dir = ws.geo_dir();
  core::EnsureDirectory(dir);
  WriteHeightGeoTiff(dir / "dsm.tif", grid, h);
  const cv::Mat shade = Hillshade(h, gsd);
  core::WriteAtomically(dir / "hillshade.png", [&](const fs::path& tmp) {
    if (!cv::imwrite(tmp.string() + ".png", shade)) throw Error((dir / "hillshade.png").string() + ": cannot write");
    fs::rename(tmp.string() + ".png", tmp);
  });
  size_t valid = 0;
  double hmin = std::numeric_limits<double>::infinity(), hmax = -hmin;
  for (int r = 0; r < h.rows; ++r)
    for (int c = 0; c < h.cols; ++c) {
      const float v = h.at<float>(r, c);
      if (std::isfinite(v)) ++valid, hmin = std::min<double>(hmin, v), hmax = std::max<double>(hmax, v);
    }
  nlohmann::json j;
  j["source"] = s.source;
  j["gsd_m"] = gsd;
  j["width"] = grid.width;
  j["height"] = grid.height;
  j["origin_utm"] = {grid.min_e, grid.max_n};
  j["epsg"] = g.utm.Epsg();
  j["crs"] = g.utm.Name();
  j["vertical_datum"] = g.vertical_datum;
  j["valid_cells"] = valid;
  j["georef_consistent_with_telemetry"] = g.consistent_with_telemetry;
  if (!g.consistent_with_telemetry)
    spdlog::warn(
        "dsm: the georeference disagrees with the telemetry (see geo/georef.json): heights and "
        "positions of this DSM are not reliable");
  j["trusted"] = g.trusted;
  if (!g.trusted) {
    j["untrusted_reason"] = g.untrusted_reason;
    spdlog::warn("dsm: NOT TRUSTED — the georeference disagrees with the telemetry: {}", g.untrusted_reason);
  }
  j["height_range_m"] = {hmin, hmax};
  const LocalFrame frame(g.origin, g.utm);
  // The absolute height error the georeference alone predicts over these cells (geo/accuracy.h): translation,
  // tilt and scale as the telemetry knows them. (UTM's grid convergence, < 2°, is ignored in the offsets.)
  if (g.accuracy && g.accuracy->rotation_known && valid > 0) {
    const Eigen::Vector3d pivot = frame.EnuToUtm(g.accuracy->pivot);
    double sq = 0;
    for (int r = 0; r < h.rows; ++r)
      for (int c = 0; c < h.cols; ++c) {
        const float v = h.at<float>(r, c);
        if (!std::isfinite(v)) continue;
        const Eigen::Vector2d e = grid.CellCentre(r, c);
        sq +=
            std::pow(g.accuracy->HeightSigma(Eigen::Vector3d(e.x() - pivot.x(), e.y() - pivot.y(), v - pivot.z())), 2);
      }
    j["expected_height_error_m"] = std::sqrt(sq / static_cast<double>(valid));
    spdlog::info("dsm: expected absolute height error from the georeference {:.3f} m RMS (1σ, telemetry alone)",
                 j["expected_height_error_m"].get<double>());
  } else {
    j["expected_height_error_m"] = nullptr;
    j["expected_height_error_why"] = g.accuracy ? "the georeference leaves a rotation unknown (straight track)"
                                                : "geo/georef.json states no expected accuracy";
  }
  const GeoPoint centre =
      frame.UtmToGeodetic({grid.min_e + 0.5 * grid.width * gsd, grid.max_n - 0.5 * grid.height * gsd, 0});
  j["centre_wgs84"] = {{"lat", centre.lat}, {"lon", centre.lon}};
  if (checked)
    j["mesh_check"] = {{"points", pts.source},
                       {"cells_checked", mesh_check.checked},
                       {"replaced_above", mesh_check.replaced_above},
                       {"replaced_below", mesh_check.replaced_below},
                       {"unmeasured_left_without_data", mesh_check.unmeasured}};
  if (o.write_las) {
    WriteLas(dir / "points.las", pts.vertices, pts.colors, UtmWkt(g.utm, /*wkt1=*/true));
    j["las_points"] = pts.vertices.size();
    j["las_source"] = pts.source;
  }
  core::WriteJson(dir / "dsm.json", j);
  return j;
}

nlohmann::json RunOrthoStage(const core::Workspace& ws) {
  const Georef g = ReadGeoref(ws);
  const fs::path dsm = ws.geo_dir() / "dsm.tif";
  if (!fs::exists(dsm))
    throw Error(ws.name() + ": no geo/dsm.tif — run `fmv3d dsm` first (the orthophoto uses its grid)");
  GridSpec grid;
  ReadHeightGeoTiff(dsm, &grid);
  cv::Mat bgr(grid.height, grid.width, CV_8UC3, cv::Scalar(0, 0, 0));
  cv::Mat valid(grid.height, grid.width, CV_8U, cv::Scalar(0));
  cv::Mat top(grid.height, grid.width, CV_32F, cv::Scalar(-std::numeric_limits<float>::infinity()));
  nlohmann::json j;
  const fs::path obj = ws.mesh_dir() / "textured.obj";
  if (fs::exists(obj)) {
    io::TexturedMesh mesh = io::ReadObj(obj, true);
    for (auto& v : mesh.vertices) v = g.sparse_to_enu.Apply(v);
    const LocalFrame frame(g.origin, g.utm);
    frame.EnuToUtm(&mesh.vertices);
    std::vector<render::MipTexture> textures(mesh.materials.size());
    tbb::parallel_for(size_t{0}, mesh.materials.size(), [&](size_t m) {
      if (!mesh.materials[m].texture.empty())
        textures[m] = render::MipTexture(mesh.materials[m].texture, 1);  // sampled at lod 0
    });
    core::Progress progress("ortho", mesh.faces.size());
    for (const auto& f : mesh.faces) {
      const auto& a = mesh.vertices[f.v[0]];
      const auto& b = mesh.vertices[f.v[1]];
      const auto& c = mesh.vertices[f.v[2]];
      const bool has_uv = f.vt[0] >= 0 && f.vt[1] >= 0 && f.vt[2] >= 0;
      const bool textured = has_uv && f.material >= 0 && !textures[f.material].empty();
      RasteriseTriangle(grid, a, b, c, [&](int r, int col, const Eigen::Vector3d& w, double z) {
        float& t = top.at<float>(r, col);
        if (z <= t) return;  // seen from above: the highest surface wins
        t = static_cast<float>(z);
        Eigen::Vector3f colour;
        if (textured) {
          const Eigen::Vector2f uv = static_cast<float>(w[0]) * mesh.uvs[f.vt[0]] +
                                     static_cast<float>(w[1]) * mesh.uvs[f.vt[1]] +
                                     static_cast<float>(w[2]) * mesh.uvs[f.vt[2]];
          colour = textures[f.material].Sample(uv.x(), uv.y(), 0);
        } else {
          colour = f.material >= 0 ? Eigen::Vector3f(mesh.materials[f.material].diffuse_bgr * 255.f)
                                   : Eigen::Vector3f(200, 200, 200);
        }
        bgr.at<cv::Vec3b>(r, col) =
            cv::Vec3b(cv::saturate_cast<uint8_t>(colour[0]), cv::saturate_cast<uint8_t>(colour[1]),
                      cv::saturate_cast<uint8_t>(colour[2]));
        valid.at<uint8_t>(r, col) = 1;
      });
      progress.Add();
    }
    progress.Finish();
    j["source"] = obj.string();
    j["faces"] = mesh.faces.size();
  } else {
    std::string source;
    io::OrientedPointCloud cloud = LoadPoints(ws, &source);
    if (!cloud.has_colors()) throw Error(source + ": the points have no colours for an orthophoto");
    ToUtm(g, &cloud.positions);
    for (size_t i = 0; i < cloud.size(); ++i) {
      const auto& p = cloud.positions[i];
      const double fc = std::floor(grid.Col(p.x())), fr = std::floor(grid.Row(p.y()));
      if (!(fr >= 0 && fc >= 0 && fr < grid.height && fc < grid.width)) continue;
      const int r = static_cast<int>(fr), c = static_cast<int>(fc);
      if (p.z() <= top.at<float>(r, c)) continue;
      top.at<float>(r, c) = static_cast<float>(p.z());
      const auto& rgb = cloud.colors[i];
      bgr.at<cv::Vec3b>(r, c) = cv::Vec3b(rgb[2], rgb[1], rgb[0]);
      valid.at<uint8_t>(r, c) = 1;
    }
    j["source"] = source;
    j["points"] = cloud.size();
    spdlog::warn("ortho: no mesh/textured.obj; using the coloured points of {}", source);
  }
  WriteRgbaGeoTiff(ws.geo_dir() / "ortho.tif", grid, bgr, valid);
  j["valid_cells"] = cv::countNonZero(valid);
  j["trusted"] = g.trusted;
  if (!g.trusted) {
    j["untrusted_reason"] = g.untrusted_reason;
    spdlog::warn("ortho: NOT TRUSTED — the georeference disagrees with the telemetry: {}", g.untrusted_reason);
  }
  j["width"] = grid.width;
  j["height"] = grid.height;
  j["gsd_m"] = grid.gsd;
  j["epsg"] = grid.zone.Epsg();
  return j;
}

}  // namespace fmv3d::geo
