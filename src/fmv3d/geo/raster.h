// North-up rasters in a UTM zone: the grid shared by the DSM and the orthophoto, a triangle rasteriser that
// keeps the highest surface per cell, GeoTIFF reading/writing (GDAL) and a hillshade for viewing.
//
// A cell (row r, column c) covers easting [min_e + c·gsd, min_e + (c+1)·gsd) and northing
// (max_n − (r+1)·gsd, max_n − r·gsd]; the value belongs to the cell centre. GDAL's geotransform is
// (min_e, gsd, 0, max_n, 0, −gsd).
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/geo/geodesy.h"

namespace fmv3d::geo {

struct GridSpec {
  double min_e = 0, max_n = 0, gsd = 1;
  int width = 0, height = 0;
  UtmZone zone;
  // Cell-centre coordinates and the (fractional) column/row of a point.
  Eigen::Vector2d CellCentre(int row, int col) const { return {min_e + (col + 0.5) * gsd, max_n - (row + 0.5) * gsd}; }
  double Col(double e) const { return (e - min_e) / gsd; }
  double Row(double n) const { return (max_n - n) / gsd; }
  // A grid covering the box with a margin of one cell, snapped to multiples of gsd.
  static GridSpec Covering(const Eigen::Vector2d& min, const Eigen::Vector2d& max, double gsd, const UtmZone& zone);
};

// Calls shade(row, col, barycentrics, height) for every cell whose centre lies in the triangle's plan
// projection (a, b, c are (E, N, h)). Vertical or degenerate triangles (zero plan area) cover no centre.
void RasteriseTriangle(const GridSpec& grid, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                       const Eigen::Vector3d& c,
                       const std::function<void(int row, int col, const Eigen::Vector3d& bary, double h)>& shade);

constexpr float kNoData = -9999.0f;

// Single-band Float32 GeoTIFF with nodata (cells equal to kNoData or NaN are written as kNoData).
void WriteHeightGeoTiff(const std::filesystem::path& path, const GridSpec& grid, const cv::Mat& height32f);
// 4-band RGBA uint8 GeoTIFF (alpha 0 where `valid` is 0). bgr: CV_8UC3, valid: CV_8U.
void WriteRgbaGeoTiff(const std::filesystem::path& path, const GridSpec& grid, const cv::Mat& bgr,
                      const cv::Mat& valid);
// Reads a single-band GeoTIFF written above (grid from its geotransform; the zone from its EPSG code).
cv::Mat ReadHeightGeoTiff(const std::filesystem::path& path, GridSpec* grid);

// Hillshade (sun azimuth 315°, elevation 45°), 0..255, black where there is no data. CV_8U.
cv::Mat Hillshade(const cv::Mat& height32f, double gsd);

}  // namespace fmv3d::geo
