// OpenDroneMap's gcp_list.txt: the CRS forms ODM writes, check points, grouping, every kind of broken line with
// its line number, unknown EPSG codes, export = import, nothing written when anything is wrong.
#include "fmv3d/geo/gcp_list.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::geo {
namespace {

using ::testing::HasSubstr;

std::vector<std::string> Problems(const std::string& text) {
  std::vector<std::string> errors;
  const GcpList list = ParseGcpList(text, &errors);
  io::FrameTable frames;
  frames["a.png"] = {640, 360};
  frames["b.png"] = {640, 360};
  CheckGcpList(list, frames, &errors);
  return errors;
}

TEST(GcpList, OdmFileWithCheckPoint) {
  const std::string text =
      "EPSG:4326\n"
      "7.4474 46.9480 560.12\t412.5 220.25 a.png gcp1\n"
      "7.4474 46.9480 560.12 398 231.75 b.png gcp1 extra_ignored\n"
      "# a comment\n\n"
      "7.4481 46.9483 561.7 80.5 120.5 a.png chk1 check\n"
      "7.4481 46.9483 561.7 81.5 121.5 b.png chk1 Check\n"
      "7.4490 46.9490 562 10 10 a.png\n"
      "7.4490 46.9490 562 11 11 b.png\n";
  EXPECT_TRUE(Problems(text).empty()) << io::JoinErrors(Problems(text));
  std::vector<std::string> errors;
  const GcpList list = ParseGcpList(text, &errors);
  ASSERT_EQ(list.lines.size(), 6u);
  EXPECT_EQ(list.lines[2].line, 6);
  const auto points = GroupGcps(list);
  ASSERT_EQ(points.size(), 3u);
  EXPECT_EQ(points[0].name, "gcp1");
  EXPECT_FALSE(points[0].check);
  EXPECT_EQ(points[0].observations.size(), 2u);
  EXPECT_TRUE(points[1].check);
  EXPECT_EQ(points[2].name, "line 8");  // unnamed: grouped by coordinates
  EXPECT_EQ(points[2].observations.size(), 2u);
  // geo_x is the longitude in EPSG:4326 (ODM's order); heights are ellipsoidal.
  GcpCrs crs(list.crs);
  const GeoPoint g = crs.ToWgs84(points[0].geo);
  EXPECT_NEAR(g.lat, 46.9480, 1e-9);
  EXPECT_NEAR(g.lon, 7.4474, 1e-9);
  EXPECT_NEAR(g.alt, 560.12, 1e-6);
  EXPECT_EQ(crs.vertical_datum(), "WGS84 ellipsoid");
  // Export = import: the formatted file parses to the same lines, extra fields kept.
  const GcpList again = ParseGcpList(FormatGcpList(list), &errors);
  ASSERT_TRUE(errors.empty());
  ASSERT_EQ(again.lines.size(), list.lines.size());
  for (size_t i = 0; i < list.lines.size(); ++i) {
    EXPECT_EQ(again.lines[i].geo, list.lines[i].geo);
    EXPECT_EQ(again.lines[i].im_x, list.lines[i].im_x);
    EXPECT_EQ(again.lines[i].image, list.lines[i].image);
    EXPECT_EQ(again.lines[i].name, list.lines[i].name);
    EXPECT_EQ(again.lines[i].extra, list.lines[i].extra);
  }
}

TEST(GcpList, CrsForms) {
  // ODM's "WGS84 UTM 32N" = EPSG:32632 = its PROJ string.
  const GeoPoint p{46.9, 7.5, 500};
  GcpCrs odm("WGS84 UTM 32N"), epsg("EPSG:32632"), proj("+proj=utm +zone=32 +datum=WGS84 +units=m +no_defs");
  EXPECT_EQ(odm.epsg(), 32632);
  const Eigen::Vector3d a = odm.FromWgs84(p), b = epsg.FromWgs84(p), c = proj.FromWgs84(p);
  EXPECT_NEAR((a - b).norm(), 0, 1e-6);
  EXPECT_NEAR((a - c).norm(), 0, 1e-6);
  EXPECT_NEAR(a.z(), 500, 1e-9);  // heights pass through: ellipsoidal
  const GeoPoint back = odm.ToWgs84(a);
  EXPECT_NEAR(back.lat, p.lat, 1e-9);
  EXPECT_NEAR(back.lon, p.lon, 1e-9);
  EXPECT_NEAR(a.x(), 385750, 100);  // easting first (west of the zone's 9° meridian)
  EXPECT_NEAR(a.y(), 5.2e6, 2e4);
  GcpCrs south("WGS84 UTM 18S");
  EXPECT_EQ(south.epsg(), 32718);
  // Another national grid with its own datum (Swiss LV95) is accepted and transformed.
  GcpCrs lv95("EPSG:2056");
  const GeoPoint bern = lv95.ToWgs84({2600000, 1200000, 500});
  EXPECT_NEAR(bern.lat, 46.95, 0.01);
  EXPECT_NEAR(bern.lon, 7.44, 0.01);
}

TEST(GcpList, EveryBrokenLineNamed) {
  auto e = Problems("EPSG:999999\n1 2 3 4 5 a.png x\n1 2 3 4 5 b.png x\n");
  ASSERT_EQ(e.size(), 1u);
  EXPECT_THAT(e[0], HasSubstr("gcp_list.txt:1: unknown CRS \"EPSG:999999\""));
  EXPECT_THAT(Problems("WGS84 UTM 61N\n").at(0), HasSubstr("gcp_list.txt:1: CRS \"WGS84 UTM 61N\": UTM zone 61"));
  EXPECT_THAT(Problems("LV95\n").at(0), HasSubstr("gcp_list.txt:1: CRS \"LV95\" is not one of"));
  EXPECT_THAT(Problems("+proj=nonsense\n").at(0), HasSubstr("gcp_list.txt:1: unknown CRS"));
  EXPECT_THAT(Problems("").at(0), HasSubstr("empty file"));
  e = Problems(
      "EPSG:4326\n"
      "7.44 46.94 560 10 20 a.png g\n"
      "7.44 46.94 560 10\n"                   // line 3: too few fields
      "7.44 46,94 560 10 20 b.png g\n"        // line 4: a decimal comma
      "7.44 46.94 nan 10 20 b.png g\n"        // line 5: not finite
      "7.44 46.94 560 10 20 missing.png g\n"  // line 6: no such frame
      "7.44 46.94 560 700 20 b.png g\n"       // line 7: outside the image
      "7.45 46.94 560 10 20 b.png g\n"        // line 8: the same name elsewhere
      "7.46 46.94 560 10 20 a.png check\n");  // line 9: a check point without a name
  ASSERT_GE(e.size(), 7u) << io::JoinErrors(e, 100);
  EXPECT_THAT(e[0], HasSubstr("gcp_list.txt:3: expected geo_x geo_y geo_z im_x im_y image_name"));
  EXPECT_THAT(e[1], HasSubstr("gcp_list.txt:4: geo_y \"46,94\" is not a number"));
  EXPECT_THAT(e[2], HasSubstr("gcp_list.txt:5: geo_z \"nan\" is not a number"));
  EXPECT_THAT(e[3], HasSubstr("gcp_list.txt:9: a check point needs a name"));
  EXPECT_THAT(e[4], HasSubstr("gcp_list.txt:8: GCP \"g\" has other coordinates than on line 2"));
  EXPECT_THAT(e[5], HasSubstr("gcp_list.txt:6: frame \"missing.png\" is not in frames/frames.json"));
  EXPECT_THAT(e[6], HasSubstr("gcp_list.txt:7: (700.00, 20.00) is outside b.png (640x360)"));
  // Coordinates that are no place in their CRS (longitude 200, latitude 95), and one point clicked twice in a frame.
  e = Problems(
      "EPSG:4326\n"
      "200 46.94 560 10 20 a.png g\n"
      "7.44 95 560 10 20 b.png g\n"
      "7.44 46.94 560 10 20 a.png h\n"
      "7.44 46.94 560 30 40 a.png h\n"
      "7.44 46.94 560 10 20 b.png h\n");
  ASSERT_EQ(e.size(), 3u) << io::JoinErrors(e, 100);
  EXPECT_THAT(e[0], HasSubstr("gcp_list.txt:2: (200, 46.94, 560) is not a place in WGS 84"));
  EXPECT_THAT(e[1], HasSubstr("gcp_list.txt:3: (7.44, 95, 560) is not a place"));
  EXPECT_THAT(e[2],
              HasSubstr("gcp_list.txt:5: GCP \"h\" is clicked a second time in frame \"a.png\" (first on line 4)"));
  // A point clicked in one frame only cannot be triangulated.
  e = Problems("EPSG:4326\n7.44 46.94 560 10 20 a.png lone\n");
  ASSERT_EQ(e.size(), 1u);
  EXPECT_THAT(e[0], HasSubstr("gcp_list.txt:2: GCP \"lone\" is clicked in 1 frame"));
}

TEST(GcpList, NothingWrittenHalfWay) {
  test::TempDir dir("fmv3d-gcp");
  const auto path = dir / "gcp_list.txt";
  io::FrameTable frames;
  frames["a.png"] = {640, 360};
  frames["b.png"] = {640, 360};
  GcpList list;
  list.crs = "EPSG:32632";
  list.lines.push_back({{500000, 5200000, 300}, 10, 20, "a.png", "g1", {}, 0});
  list.lines.push_back({{500000, 5200000, 300}, 11, 21, "b.png", "g1", {}, 0});
  WriteGcpList(list, path, &frames);
  const std::string before = core::ReadTextFile(path);
  EXPECT_EQ(ReadGcpList(path, &frames).lines.size(), 2u);
  GcpList bad = list;
  bad.crs = "EPSG:999999";
  EXPECT_THROW(WriteGcpList(bad, path, &frames), Error);
  bad = list;
  bad.lines[1].image = "nope.png";
  try {
    WriteGcpList(bad, path, &frames);
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("not saved"));
    EXPECT_THAT(e.what(), HasSubstr(":3: frame \"nope.png\""));
  }
  EXPECT_EQ(core::ReadTextFile(path), before);
}

}  // namespace
}  // namespace fmv3d::geo
