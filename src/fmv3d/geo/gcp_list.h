// Ground control points in OpenDroneMap's gcp_list.txt format (WS/manual/gcp_list.txt; docs/manual-inputs.md):
//   line 1:  the CRS — "EPSG:<code>" (or "EPSG:<h>+<v>", compound), "WGS84 UTM <zone><N|S>", or a PROJ string
//            "+proj=..."
//   then:    geo_x geo_y geo_z im_x im_y image_name [gcp_name] [extra ...]   (spaces or tabs)
// geo_x is the easting / longitude, geo_y the northing / latitude (ODM's order), geo_z the height as the CRS
// defines it (ellipsoidal for EPSG:4326 and the WGS84 UTM codes); im_x, im_y are fmv3d pixels of the frame
// image_name (origin at the top-left corner, pixel centres at +0.5). A check point carries "check" (or
// "checkpoint") as the first extra field after its name: ODM ignores extra fields, fmv3d leaves the point out of
// the fit. Blank lines and lines starting with '#' are skipped.
//
// Errors name the file and the line ("gcp_list.txt:7: ..."); parsing collects all of them. The CRS is resolved
// through GDAL/OGR (PROJ's database), so an unknown EPSG code is an error on line 1.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "fmv3d/geo/geodesy.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::geo {

struct GcpLine {
  Eigen::Vector3d geo = Eigen::Vector3d::Zero();  // geo_x geo_y geo_z in the file's CRS
  double im_x = 0, im_y = 0;
  std::string image, name;
  std::vector<std::string> extra;  // fields after the name, kept for export
  int line = 0;                    // 1-based line in the file (0: not read from a file)
  bool IsCheck() const;            // the first extra field is "check" / "checkpoint"
};

struct GcpList {
  std::string crs;  // line 1 as written, trimmed
  std::vector<GcpLine> lines;
};

// Resolves a CRS line (see above) and converts its coordinates to WGS84 geodetic (lat, lon, ellipsoidal height).
class GcpCrs {
 public:
  // Throws fmv3d::Error naming the CRS and GDAL's reason when it is not one of the accepted forms or unknown.
  explicit GcpCrs(const std::string& crs);
  ~GcpCrs();
  GcpCrs(const GcpCrs&) = delete;
  GcpCrs& operator=(const GcpCrs&) = delete;

  const std::string& name() const { return name_; }  // the CRS's name, e.g. "WGS 84 / UTM zone 32N"
  int epsg() const { return epsg_; }                 // 0 when it has none (PROJ string)
  // "WGS84 ellipsoid" for CRSs without a vertical component (their heights are taken as ellipsoidal), else the
  // vertical CRS's name (heights converted to ellipsoidal by PROJ).
  const std::string& vertical_datum() const { return vertical_datum_; }
  // Throws fmv3d::Error when PROJ cannot transform the point.
  GeoPoint ToWgs84(const Eigen::Vector3d& geo) const;
  // The inverse, for export and tests.
  Eigen::Vector3d FromWgs84(const GeoPoint& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string name_, vertical_datum_;
  int epsg_ = 0;
};

// Parses the text; one message per problem ("<what>:<line>: ...") is appended to *errors (CRS unknown, wrong field
// count, numbers that are not numbers or not finite, a check point without a name, one name with two different
// coordinates). Returns what could be read.
GcpList ParseGcpList(const std::string& text, std::vector<std::string>* errors,
                     const std::string& what = "gcp_list.txt");
// The file form: the CRS line, then one line per observation (extra fields kept), numbers in full precision.
std::string FormatGcpList(const GcpList& list);

// Against a workspace's frames: image names that exist and pixels inside the image ("<what>:<line>: ...").
void CheckGcpList(const GcpList& list, const io::FrameTable& frames, std::vector<std::string>* errors,
                  const std::string& what = "gcp_list.txt");

// Reads, parses and (with `frames`) checks; throws fmv3d::Error listing every problem.
GcpList ReadGcpList(const std::filesystem::path& path, const io::FrameTable* frames = nullptr);
// Checks (parse of the formatted text, and `frames` when given), then writes atomically; on any problem throws
// and leaves `path` untouched.
void WriteGcpList(const GcpList& list, const std::filesystem::path& path, const io::FrameTable* frames = nullptr);

// One ground point: its lines grouped by name (or, unnamed, by identical coordinates).
struct GroundControlPoint {
  std::string name;  // the file's name, or "line N" for an unnamed point
  bool check = false;
  Eigen::Vector3d geo = Eigen::Vector3d::Zero();  // in the file's CRS
  std::vector<io::ImagePoint> observations;
  int first_line = 0;
};
std::vector<GroundControlPoint> GroupGcps(const GcpList& list);

}  // namespace fmv3d::geo
