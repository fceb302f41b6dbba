// Terrain products of a georeferenced workspace (`fmv3d dsm WS`, `fmv3d ortho WS`).
//
// Surface, first found: WS/mesh/poisson.ply (triangles rasterised), WS/dense/fused.ply, the sparse model's
// points (WS/sparse/). Everything is mapped sparse frame → ENU (georef.json's similarity) → UTM (the zone of
// georef.json); heights keep georef.json's vertical datum.
//
// dsm:   WS/geo/dsm.tif        Float32 GeoTIFF, highest surface per cell (points: their median height per
//                              cell, see RasteriseDsm; a mesh checked against the dense points, see
//                              CheckMeshHeights), nodata (-9999) where unseen
//        WS/geo/hillshade.png  for viewing
//        WS/geo/points.las     LAS 1.4 with the UTM CRS: the dense points, else the sparse points
//        WS/geo/dsm.json       grid, source, counts
// ortho: WS/geo/ortho.tif      RGBA GeoTIFF on the DSM's grid: WS/mesh/textured.obj seen from straight above
//                              (orthographic, the top-most surface per cell), else the top-most coloured point
//                              per cell; alpha 0 where nothing is seen
//
// Ground sample distance (dsm, unless given): for a mesh the median plan length of its edges; for points
// √2 × the mean point spacing over the occupied area (about two points per cell), at least 1 cm; widened when
// the grid would exceed max_cells.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/geo/raster.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::geo {

struct DsmOptions {
  std::optional<double> gsd;  // metres
  double max_cells = 64e6;
  bool write_las = true;
  void Check() const;
};

// The surface a DSM is made of, in UTM (E, N, h).
struct UtmSurface {
  std::string source;                      // the file used
  std::vector<Eigen::Vector3d> vertices;   // mesh vertices or points
  std::vector<Eigen::Vector3i> triangles;  // empty for points
  std::vector<io::Rgb8> colors;            // per vertex / point, may be empty
};

// Loads the first available surface (see above) and maps it to UTM. Throws fmv3d::Error when none exists.
UtmSurface LoadUtmSurface(const core::Workspace& workspace, const Georef& georef);

// Height per cell; NaN where nothing lands. A mesh gives the highest surface: triangles cover the cells whose
// centres they contain, and their vertices mark their own cells (so thin or steep triangles still count).
// Points give the median of the points in the cell (robust to their noise, which a maximum would pick up).
cv::Mat RasteriseDsm(const UtmSurface& surface, const GridSpec& grid);
// See the header comment.
double ChooseGsd(const UtmSurface& surface);

// A mesh's heights checked against the points it was made from. Poisson closes what the cameras did not see
// with a smooth membrane (beside walls a nadir flight does not see, behind occluders) and can fit blobs to
// clusters of outlier points; the highest surface of such a mesh stands above ground the cameras measured.
// Each cell's mesh height is compared with the heights of the points within `window` cells around it: when
// at least `min_points` are there and the mesh lies outside [q25 − tol, q75 + tol] of their heights (tol: the
// larger of their median stated σ and one cell size), the cell takes their median. The quartiles let a few
// points of a blob or a wall not decide; a surface that the points there support (a roof edge, steep ground,
// far land with a large σ) keeps the mesh's height. A cell with fewer points than that is still overruled
// where its mesh stands above every one of the points within `max_gap` cells (at least `min_points_near`) by
// more than tol: a roof that Poisson carried past a wall over the gap of unseen ground at its foot, which no
// point supports. Other cells without enough points keep the mesh's height.
// A cell with no point within `max_gap` cells is left without data: there the mesh is Poisson's guess over
// ground no camera measured (beside the walls of a nadir flight, behind occluders), not a measurement.
struct MeshCheckOptions {
  int window = 1;              // cells on each side of the checked one
  size_t min_points = 6;       // points in the window needed to overrule the mesh
  int max_gap = 3;             // cells; < 0: keep the mesh everywhere
  size_t min_points_near = 3;  // points within max_gap that overrule a mesh standing above all of them
};
struct MeshCheckStats {
  size_t checked = 0;         // cells with a mesh height and enough points
  size_t replaced_above = 0;  // mesh above what the points allow
  size_t replaced_below = 0;  // mesh below what the points allow
  size_t unmeasured = 0;      // cells left without data: no point within max_gap
};
// `points` in UTM (E, N, h); `sigma` empty or one stated σ in metres per point.
cv::Mat CheckMeshHeights(const cv::Mat& mesh_heights, const std::vector<Eigen::Vector3d>& points,
                         const std::vector<float>& sigma, const GridSpec& grid, const MeshCheckOptions& options,
                         MeshCheckStats* stats);

nlohmann::json RunDsmStage(const core::Workspace& workspace, const DsmOptions& options = {});
nlohmann::json RunOrthoStage(const core::Workspace& workspace);

}  // namespace fmv3d::geo
