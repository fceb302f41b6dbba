#include "fmv3d/geo/raster.h"

#include <fmt/format.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <cmath>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"

namespace fmv3d::geo {
namespace fs = std::filesystem;

GridSpec GridSpec::Covering(const Eigen::Vector2d& min, const Eigen::Vector2d& max, double gsd, const UtmZone& zone) {
  if (!(gsd > 0) || !min.allFinite() || !max.allFinite()) throw Error("raster: bad grid extent or cell size");
  GridSpec g;
  g.gsd = gsd;
  g.zone = zone;
  g.min_e = (std::floor(min.x() / gsd) - 1) * gsd;
  g.max_n = (std::ceil(max.y() / gsd) + 1) * gsd;
  const double max_e = (std::ceil(max.x() / gsd) + 1) * gsd, min_n = (std::floor(min.y() / gsd) - 1) * gsd;
  g.width = static_cast<int>(std::lround((max_e - g.min_e) / gsd));
  g.height = static_cast<int>(std::lround((g.max_n - min_n) / gsd));
  return g;
}

void RasteriseTriangle(const GridSpec& g, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                       const std::function<void(int, int, const Eigen::Vector3d&, double)>& shade) {
  // Work in fractional (col, row) space: cell centres are at integer + 0.5.
  const Eigen::Vector2d pa(g.Col(a.x()), g.Row(a.y())), pb(g.Col(b.x()), g.Row(b.y())), pc(g.Col(c.x()), g.Row(c.y()));
  const double area = (pb - pa).x() * (pc - pa).y() - (pb - pa).y() * (pc - pa).x();
  if (std::abs(area) < 1e-12) return;
  // Bounds clamped in double first: a far-away vertex must not overflow the int conversion.
  auto clampi = [](double v, int hi) { return static_cast<int>(std::clamp(v, -1.0, static_cast<double>(hi))); };
  const int c0 = std::max(0, clampi(std::floor(std::min({pa.x(), pb.x(), pc.x()}) - 0.5), g.width));
  const int c1 = std::min(g.width - 1, clampi(std::ceil(std::max({pa.x(), pb.x(), pc.x()}) - 0.5), g.width));
  const int r0 = std::max(0, clampi(std::floor(std::min({pa.y(), pb.y(), pc.y()}) - 0.5), g.height));
  const int r1 = std::min(g.height - 1, clampi(std::ceil(std::max({pa.y(), pb.y(), pc.y()}) - 0.5), g.height));
  if (!pa.allFinite() || !pb.allFinite() || !pc.allFinite()) return;
  for (int r = r0; r <= r1; ++r)
    for (int col = c0; col <= c1; ++col) {
      const Eigen::Vector2d p(col + 0.5, r + 0.5);
      const double wa = ((pb - p).x() * (pc - p).y() - (pb - p).y() * (pc - p).x()) / area;
      const double wb = ((pc - p).x() * (pa - p).y() - (pc - p).y() * (pa - p).x()) / area;
      const double wc = 1 - wa - wb;
      if (wa < -1e-9 || wb < -1e-9 || wc < -1e-9) continue;
      shade(r, col, Eigen::Vector3d(wa, wb, wc), wa * a.z() + wb * b.z() + wc * c.z());
    }
}

namespace {

struct DatasetCloser {
  GDALDataset* ds;
  ~DatasetCloser() {
    if (ds) GDALClose(ds);
  }
};

// The raster is assembled in memory (GDAL's MEM driver) and then copied out by the COG driver, which only
// writes by copy: tiled, DEFLATE-compressed, with overviews, laid out as a Cloud-Optimised GeoTIFF (gdalinfo
// reports LAYOUT=COG) that map clients read by HTTP range requests.
GDALDataset* CreateMemRaster(const fs::path& path, const GridSpec& g, int bands, GDALDataType type) {
  GDALAllRegister();
  GDALDriver* drv = GetGDALDriverManager()->GetDriverByName("MEM");
  if (!drv) throw Error("GDAL: no MEM driver");
  if (g.width <= 0 || g.height <= 0) throw Error(path.string() + ": empty raster");
  GDALDataset* ds = drv->Create("", g.width, g.height, bands, type, nullptr);
  if (!ds) throw Error(path.string() + ": GDAL cannot allocate the raster: " + CPLGetLastErrorMsg());
  double gt[6] = {g.min_e, g.gsd, 0, g.max_n, 0, -g.gsd};
  ds->SetGeoTransform(gt);
  OGRSpatialReference srs;
  srs.importFromEPSG(g.zone.Epsg());
  ds->SetSpatialRef(&srs);
  return ds;
}

void WriteCog(GDALDataset* mem, const fs::path& path) {
  GDALDriver* drv = GetGDALDriverManager()->GetDriverByName("COG");
  if (!drv) throw Error("GDAL: no COG driver (GDAL 3.1 or later is needed)");
  char** opts = nullptr;
  opts = CSLSetNameValue(opts, "COMPRESS", "DEFLATE");
  opts = CSLSetNameValue(opts, "BIGTIFF", "IF_SAFER");
  GDALDataset* out = drv->CreateCopy(path.c_str(), mem, FALSE, opts, nullptr, nullptr);
  CSLDestroy(opts);
  if (!out) throw Error(path.string() + ": GDAL cannot write the COG: " + CPLGetLastErrorMsg());
  GDALClose(out);
}

}  // namespace

void WriteHeightGeoTiff(const fs::path& path, const GridSpec& g, const cv::Mat& h) {
  if (h.type() != CV_32F || h.rows != g.height || h.cols != g.width)
    throw Error(path.string() + ": raster size mismatch");
  cv::Mat out = h.clone();
  out.forEach<float>([](float& v, const int*) {
    if (!std::isfinite(v)) v = kNoData;
  });
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    GDALDataset* ds = CreateMemRaster(tmp, g, 1, GDT_Float32);
    DatasetCloser closer{ds};
    GDALRasterBand* band = ds->GetRasterBand(1);
    band->SetNoDataValue(kNoData);
    band->SetDescription("height (m)");
    if (band->RasterIO(GF_Write, 0, 0, g.width, g.height, out.ptr<float>(), g.width, g.height, GDT_Float32, 0,
                       static_cast<int>(out.step[0])) != CE_None)
      throw Error(path.string() + ": GDAL write failed: " + CPLGetLastErrorMsg());
    WriteCog(ds, tmp);
  });
}

void WriteRgbaGeoTiff(const fs::path& path, const GridSpec& g, const cv::Mat& bgr, const cv::Mat& valid) {
  if (bgr.type() != CV_8UC3 || valid.type() != CV_8U || bgr.rows != g.height || bgr.cols != g.width ||
      valid.size() != bgr.size())
    throw Error(path.string() + ": raster size mismatch");
  std::vector<cv::Mat> ch;
  cv::split(bgr, ch);
  cv::Mat alpha = valid.clone();
  alpha.setTo(255, valid);
  const cv::Mat planes[4] = {ch[2], ch[1], ch[0], alpha};  // R, G, B, A
  core::WriteAtomically(path, [&](const fs::path& tmp) {
    GDALDataset* ds = CreateMemRaster(tmp, g, 4, GDT_Byte);
    DatasetCloser closer{ds};
    for (int b = 0; b < 4; ++b) {
      const cv::Mat p = planes[b].isContinuous() ? planes[b] : planes[b].clone();
      GDALRasterBand* band = ds->GetRasterBand(b + 1);
      band->SetColorInterpretation(b == 0   ? GCI_RedBand
                                   : b == 1 ? GCI_GreenBand
                                   : b == 2 ? GCI_BlueBand
                                            : GCI_AlphaBand);
      if (band->RasterIO(GF_Write, 0, 0, g.width, g.height, const_cast<uint8_t*>(p.ptr<uint8_t>()), g.width, g.height,
                         GDT_Byte, 0, 0) != CE_None)
        throw Error(path.string() + ": GDAL write failed: " + CPLGetLastErrorMsg());
    }
    WriteCog(ds, tmp);
  });
}

cv::Mat ReadHeightGeoTiff(const fs::path& path, GridSpec* grid) {
  GDALAllRegister();
  GDALDataset* ds = static_cast<GDALDataset*>(GDALOpen(path.c_str(), GA_ReadOnly));
  if (!ds) throw Error(path.string() + ": GDAL cannot open it: " + CPLGetLastErrorMsg());
  DatasetCloser closer{ds};
  double gt[6];
  if (ds->GetGeoTransform(gt) != CE_None || gt[2] != 0 || gt[4] != 0 || !(gt[1] > 0) || std::abs(gt[1] + gt[5]) > 1e-9)
    throw Error(path.string() + ": not a north-up raster with square cells");
  GridSpec g;
  g.min_e = gt[0];
  g.max_n = gt[3];
  g.gsd = gt[1];
  g.width = ds->GetRasterXSize();
  g.height = ds->GetRasterYSize();
  const OGRSpatialReference* srs = ds->GetSpatialRef();
  int zone = 0, north = 1;
  if (!srs || (zone = srs->GetUTMZone(&north)) == 0) throw Error(path.string() + ": not in a UTM CRS");
  g.zone = {zone, north != 0};
  cv::Mat h(g.height, g.width, CV_32F);
  if (ds->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, g.width, g.height, h.ptr<float>(), g.width, g.height, GDT_Float32,
                                     0, 0) != CE_None)
    throw Error(path.string() + ": GDAL read failed: " + CPLGetLastErrorMsg());
  int has_nodata = 0;
  const double nd = ds->GetRasterBand(1)->GetNoDataValue(&has_nodata);
  if (has_nodata)
    h.forEach<float>([nd](float& v, const int*) {
      if (v == static_cast<float>(nd)) v = std::numeric_limits<float>::quiet_NaN();
    });
  if (grid) *grid = g;
  return h;
}

cv::Mat Hillshade(const cv::Mat& h, double gsd) {
  cv::Mat out(h.size(), CV_8U, cv::Scalar(0));
  const double az = (360.0 - 315.0 + 90.0) * M_PI / 180, zen = (90.0 - 45.0) * M_PI / 180;
  auto at = [&](int r, int c, float fallback) {
    r = std::clamp(r, 0, h.rows - 1);
    c = std::clamp(c, 0, h.cols - 1);
    const float v = h.at<float>(r, c);
    return std::isfinite(v) ? v : fallback;
  };
  for (int r = 0; r < h.rows; ++r)
    for (int c = 0; c < h.cols; ++c) {
      const float z = h.at<float>(r, c);
      if (!std::isfinite(z)) continue;
      // Horn's slope from the 3x3 neighbourhood (missing neighbours take the centre's height).
      const double a = at(r - 1, c - 1, z), b = at(r - 1, c, z), cc = at(r - 1, c + 1, z);
      const double d = at(r, c - 1, z), f = at(r, c + 1, z);
      const double g = at(r + 1, c - 1, z), hh = at(r + 1, c, z), i = at(r + 1, c + 1, z);
      const double dzdx = ((cc + 2 * f + i) - (a + 2 * d + g)) / (8 * gsd);
      const double dzdy = ((g + 2 * hh + i) - (a + 2 * b + cc)) / (8 * gsd);
      const double slope = std::atan(std::hypot(dzdx, dzdy));
      const double aspect = std::atan2(dzdy, -dzdx);
      const double v = std::cos(zen) * std::cos(slope) + std::sin(zen) * std::sin(slope) * std::cos(az - aspect);
      out.at<uint8_t>(r, c) = static_cast<uint8_t>(std::clamp(1 + 254 * v, 1.0, 255.0));
    }
  return out;
}

}  // namespace fmv3d::geo
