// Georef's measurements: (model camera, telemetry) pairs. A registered keyframe pairs with its own telemetry
// (named); with the videos' whole tracks (frames/telemetry.json), every packet inside the registered span of its
// video pairs with the model's camera at that time (CameraTrajectory through the registered keyframes, never
// across a gap) — 30 packets a second instead of ~2 keyframes, so white GPS noise averages ~4x further.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::geo {

enum class VerticalDatum { kEllipsoid, kMsl };
const char* VerticalDatumName(VerticalDatum d);  // "WGS84 ellipsoid", "MSL"
// nullopt for another name (a GCP list's CRS names its own vertical datum).
std::optional<VerticalDatum> ParseVerticalDatum(const std::string& name);

// One (model camera, telemetry) correspondence.
struct GeorefPair {
  std::string name;                         // the keyframe's; empty for a track packet
  Eigen::Vector3d centre;                   // model camera centre
  Eigen::Quaterniond rotation;              // model world-to-camera
  GeoPoint pos;                             // sensor position, alt in the chosen datum
  std::optional<double> hae, msl;           // the sensor's heights as stated
  std::optional<Eigen::Matrix3d> attitude;  // telemetry camera-to-ENU (the full ST 0601 angle chain)
  std::optional<GeoPoint> frame_centre;     // latitude, longitude (alt unused)
  std::optional<double> frame_centre_hae, frame_centre_msl;
  std::optional<double> slant_range;
  double time = 0;
  int track = -1;  // video of a packet pair; -1 for keyframes
};

struct PairedTelemetry {
  std::vector<GeorefPair> keyframes;                // registered keyframes with a telemetry position
  std::vector<GeorefPair> track;                    // track packets; empty unless they outnumber the keyframes
  size_t frames_with_position = 0;                  // keyframes with a position, registered or not
  bool track_file = false;                          // a telemetry.json was given
  size_t track_samples = 0, track_spanned = 0;      // its packets with a position, and those inside the model's span
  VerticalDatum datum = VerticalDatum::kEllipsoid;  // of every pair's pos.alt

  bool use_track() const { return !track.empty(); }
  const std::vector<GeorefPair>& fit() const { return use_track() ? track : keyframes; }
};

// Telemetry camera-to-ENU rotation of a sample with the full ST 0601 angle chain, else nullopt.
std::optional<Eigen::Matrix3d> TelemetryAttitude(const telemetry::TelemetrySample& s);

// Pairs the model with the telemetry (see above); tracks may be null. One vertical datum for every pair:
// ellipsoidal heights when every fitted sample states them, else MSL. Throws fmv3d::Error (prefixed `where`) when
// no frame carries a position, a frame's telemetry is malformed, or fewer than min_cameras registered keyframes
// have a position.
PairedTelemetry PairTelemetry(const io::FramesIndex& index, const core::Reconstruction& model,
                              const std::vector<telemetry::TelemetryTrack>* tracks, int min_cameras,
                              const std::string& where);

// The height of a pair's frame centre implied by its slant range: the point at that range on the line of sight
// through the frame centre's latitude and longitude, i.e. the sensor's height (pos.alt, the pair's datum) minus
// √(r² − d²), d the horizontal distance (ENU of `frame`). A platform without a terrain model states where its line
// of sight meets the ellipsoid or sea level, and that point's range: this recovers its height when the packet
// does not state it. nullopt without a frame centre and a slant range longer than d.
std::optional<double> FrameCentreHeightFromRange(const GeorefPair& p, const LocalFrame& frame);

// The centroid of the fitted positions (mean in ECEF through a provisional frame, exact for any spread).
GeoPoint TelemetryCentroid(const std::vector<GeorefPair>& pairs);

// Lag-1 autocorrelation of consecutive residual vectors along each track (flagged entries only), in [0, 0.999]:
// GPS errors that persist over several packets (a receiver updating slower than the video, multipath) count as
// fewer independent samples, n·(1−ρ)/(1+ρ).
double ResidualAutocorrelation(const std::vector<GeorefPair>& pairs, const std::vector<Eigen::Vector3d>& residual,
                               const std::vector<char>& flagged);

}  // namespace fmv3d::geo
