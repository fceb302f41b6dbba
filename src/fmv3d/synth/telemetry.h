// Synthetic FMV telemetry (`fmv3d synth --klv`): the exact truth cameras, placed on the globe around a
// geographic origin, turned into one MISB ST 0601 record per frame with GPS and attitude noise.
//
// The synthetic world is a local East-North-Up frame (x east, y north, z up, metres) whose origin is
// `geo_origin` (WGS84 latitude, longitude, height). Heights: the altitude written as "true altitude" (MSL) is
// the ellipsoidal height (the synthetic globe has no geoid), and the same value goes to tag 75 (HAE).
//
// Noise model: each packet's position gets independent N(0, gps_noise²) per ENU axis (metres); the platform
// heading, pitch and roll each get independent N(0, attitude_noise²) (degrees), so the attitude the
// packet states is off by about that much; the sensor's relative angles are exact for the stated platform
// attitude. The platform heads along the horizontal direction of flight.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/io/exif.h"
#include "fmv3d/telemetry/gpmf_writer.h"
#include "fmv3d/telemetry/klv_st0601_writer.h"

namespace fmv3d::synth {

struct GeoPoint {
  double lat = 0, lon = 0, alt = 0;  // degrees, degrees, metres above the WGS84 ellipsoid
};

// WGS84 geodetic ↔ ECEF ↔ local ENU at an origin (closed-form forward, iterated inverse to < 1e-9 m).
// An independent implementation from geo/ (which uses PROJ), so each can test the other.
Eigen::Vector3d GeodeticToEcef(const GeoPoint& p);
GeoPoint EcefToGeodetic(const Eigen::Vector3d& ecef);
GeoPoint EnuToGeodetic(const Eigen::Vector3d& enu, const GeoPoint& origin);
Eigen::Vector3d GeodeticToEnu(const GeoPoint& p, const GeoPoint& origin);

struct KlvTelemetryOptions {
  GeoPoint origin{38.1600, -77.3500, 60.0};  // somewhere in Virginia (near the KWIVER sample videos)
  double gps_noise = 3;                      // metres, 1 sigma per axis
  double attitude_noise = 1;                 // degrees, 1 sigma per platform angle
  double fps = 10;
  uint64_t start_unix_us = 1717243200000000ull;  // 2024-06-01T12:00:00Z
  uint64_t seed = 1;
  // EGM96 undulation N at the origin (m): the heights MSL (tags 15, 25) are the ellipsoidal ones (75, 78) − N.
  // Set by the CLI from PROJ's grid (geo::GeoidUndulation); this module stays independent of PROJ.
  double geoid_undulation = 0;
  void Check() const;
};

// One record per pose (the frame's time is k / fps). Frame centre: where the optical axis meets the plane
// z = ground_z (omitted when it points above the horizon).
std::vector<telemetry::klv::St0601Record> MakeKlvTelemetry(const std::vector<core::Pose>& poses,
                                                           const core::Camera& camera, double ground_z,
                                                           const KlvTelemetryOptions& options);

// Photo metadata of one frame as a DJI drone writes it (`fmv3d synth --exif-gps`), from its ST 0601 record
// (so the same noise model holds): EXIF GPS at the record's noisy position, altitude = its true altitude (MSL,
// the datum EXIF and DJI use), DOP 1, GPSHPositioningError = gps_noise, GPS time; make "fmv3d", model "synth",
// the focal in mm of a 13.2 mm wide sensor with that sensor's focal-plane resolution and the image width, the 35 mm
// equivalent focal (rounded to whole mm, as cameras write it); and a DJI XMP packet with the stated
// attitude (gimbal angles of the record's camera rotation, flight angles = its platform angles),
// AbsoluteAltitude (MSL) and RelativeAltitude (ellipsoidal height above the geo origin).
struct PhotoMetadata {
  io::ExifInfo exif;  // the fields EncodeTiffExif writes
  std::string xmp;
};
PhotoMetadata MakePhotoMetadata(const telemetry::klv::St0601Record& record, const core::Camera& camera,
                                const KlvTelemetryOptions& options);

// One GPMF payload (`fmv3d synth --gpmf`) for frames [first, last): one GPS5 (GPS9 with `gps9`) fix per frame at
// the records' noisy positions (ellipsoidal heights, GPMF's datum), speeds from the true centres, and CORI: the
// exact camera rotation relative to frame 0 (R_0 R_k^T as w, x, y, z, in our camera axes).
telemetry::gpmf::PayloadContent MakeGpmfPayload(const std::vector<telemetry::klv::St0601Record>& records,
                                                const std::vector<core::Pose>& poses, size_t first, size_t last,
                                                double fps, bool gps9);

}  // namespace fmv3d::synth
