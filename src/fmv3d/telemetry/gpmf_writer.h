// GPMF writer (the inverse of gpmf.h, for test data: `fmv3d synth --gpmf`): one payload as a GoPro camera
// writes it, a DEVC with DVID/DVNM and one STRM per stream:
//   GPS5: STNM, UNIT (deg, deg, m, m/s, m/s), SCAL (1e7, 1e7, 1000, 1000, 100), GPSF, GPSU, GPSP, GPS5 'l'×5;
//   GPS9 instead, with gps9: a complex structure (TYPE "lllllllSS", SCAL 1e7, 1e7, 1000, 1000, 100, 1, 1000,
//        100, 1) of lat, lon, alt, 2D speed, 3D speed, days since 2000, seconds since midnight, DOP, fix;
//   CORI: SCAL 32767, 's'×4 quaternions (w, x, y, z).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace fmv3d::telemetry::gpmf {

struct GpsFix {
  double latitude = 0, longitude = 0, altitude = 0;  // degrees, metres (WGS84 ellipsoid)
  double speed_2d = 0, speed_3d = 0;                 // m/s
  double unix_seconds = 0;                           // UTC (GPS9 per sample; GPS5 writes the first as GPSU)
};

struct PayloadContent {
  std::string device_name = "fmv3d synth";
  std::vector<GpsFix> gps;
  bool gps9 = false;
  double gps_fix = 3;                              // GPSF / GPS9 fix: 0, 2 or 3
  double gps_dop = 1;                              // GPSP / 100, GPS9 DOP
  std::vector<std::array<double, 4>> orientation;  // CORI (w, x, y, z), unit quaternions
};

// Throws fmv3d::Error when a value does not fit its field (a latitude beyond ±90°, more than 65535 samples).
std::vector<uint8_t> EncodePayload(const PayloadContent& content);

}  // namespace fmv3d::telemetry::gpmf
