// LAS 1.4 point clouds (ASPRS R15): point data record format 7 (x y z, RGB, GPS time) with the CRS as an OGC
// WKT variable-length record ("LASF_Projection", 2112; global-encoding WKT bit set), coordinates stored as
// 32-bit integers at 1 mm with the offset at the cloud's minimum. Written by hand: the format is small and
// no LAS library is a Debian dependency here.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "fmv3d/io/point_cloud.h"

namespace fmv3d::geo {

// points: (E, N, h) in the CRS described by `wkt`; colors: empty or one per point. The header's creation day is
// today's (GMT), or that of SOURCE_DATE_EPOCH when it is set (the reproducible-builds convention: then two runs
// write the same bytes).
void WriteLas(const std::filesystem::path& path, const std::vector<Eigen::Vector3d>& points,
              const std::vector<io::Rgb8>& colors, const std::string& wkt);

struct LasInfo {
  int version_major = 0, version_minor = 0;
  int point_format = 0, point_record_length = 0;
  int creation_day = 0, creation_year = 0;  // GMT day of the year (1 = January 1st) and year
  uint64_t num_points = 0;
  Eigen::Vector3d scale, offset, min, max;
  std::string wkt;                      // from the LASF_Projection 2112 record, empty if none
  std::vector<Eigen::Vector3d> points;  // decoded coordinates (when read_points)
};
// Reads a LAS 1.4 header (and optionally the points of formats 6-10); throws fmv3d::Error when the file is
// not LAS or is truncated.
LasInfo ReadLas(const std::filesystem::path& path, bool read_points = false);

}  // namespace fmv3d::geo
