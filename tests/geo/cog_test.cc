// The DSM and ortho GeoTIFFs are Cloud-Optimised (GDAL's COG driver): GDAL reports LAYOUT=COG, as gdalinfo
// prints it, and the heights read back unchanged.
#include <gdal_priv.h>
#include <gtest/gtest.h>

#include "fmv3d/geo/raster.h"
#include "test_util.h"

namespace fmv3d::geo {
namespace {

std::string Layout(const std::filesystem::path& path) {
  GDALAllRegister();
  GDALDataset* ds = static_cast<GDALDataset*>(GDALOpen(path.c_str(), GA_ReadOnly));
  if (!ds) return "unreadable";
  const char* layout = ds->GetMetadataItem("LAYOUT", "IMAGE_STRUCTURE");
  std::string out = layout ? layout : "none";
  GDALClose(ds);
  return out;
}

GridSpec Grid(int w, int h) {
  GridSpec g;
  g.min_e = 500000;
  g.max_n = 5200000;
  g.gsd = 0.5;
  g.width = w;
  g.height = h;
  g.zone = {32, true};
  return g;
}

TEST(Cog, DsmIsACogAndReadsBack) {
  test::TempDir tmp("cog");
  const GridSpec g = Grid(700, 600);  // larger than one 512 block: overviews are built
  cv::Mat h(g.height, g.width, CV_32F);
  for (int r = 0; r < h.rows; ++r)
    for (int c = 0; c < h.cols; ++c) h.at<float>(r, c) = (r + c) % 17 == 0 ? kNoData : 100.0f + 0.01f * r - 0.02f * c;
  WriteHeightGeoTiff(tmp / "dsm.tif", g, h);
  EXPECT_EQ(Layout(tmp / "dsm.tif"), "COG");
  GridSpec back;
  const cv::Mat read = ReadHeightGeoTiff(tmp / "dsm.tif", &back);
  EXPECT_EQ(back.width, g.width);
  EXPECT_EQ(back.height, g.height);
  EXPECT_DOUBLE_EQ(back.gsd, g.gsd);
  EXPECT_EQ(back.zone.Epsg(), 32632);
  EXPECT_EQ(cv::norm(read, h, cv::NORM_INF), 0.0);
}

TEST(Cog, OrthoIsACogWithAlpha) {
  test::TempDir tmp("cog");
  const GridSpec g = Grid(300, 200);
  cv::Mat bgr(g.height, g.width, CV_8UC3, cv::Scalar(10, 20, 30));
  cv::Mat valid(g.height, g.width, CV_8U, cv::Scalar(1));
  valid(cv::Rect(0, 0, 50, 50)).setTo(0);
  WriteRgbaGeoTiff(tmp / "ortho.tif", g, bgr, valid);
  EXPECT_EQ(Layout(tmp / "ortho.tif"), "COG");
  GDALDataset* ds = static_cast<GDALDataset*>(GDALOpen((tmp / "ortho.tif").c_str(), GA_ReadOnly));
  ASSERT_NE(ds, nullptr);
  EXPECT_EQ(ds->GetRasterCount(), 4);
  EXPECT_EQ(ds->GetRasterBand(4)->GetColorInterpretation(), GCI_AlphaBand);
  uint8_t px[4];
  for (int b = 0; b < 4; ++b)
    ASSERT_EQ(ds->GetRasterBand(b + 1)->RasterIO(GF_Read, 100, 100, 1, 1, &px[b], 1, 1, GDT_Byte, 0, 0), CE_None);
  EXPECT_EQ(px[0], 30);  // R
  EXPECT_EQ(px[2], 10);  // B
  EXPECT_EQ(px[3], 255);
  GDALClose(ds);
}

}  // namespace
}  // namespace fmv3d::geo
