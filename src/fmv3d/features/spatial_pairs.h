// `spatial` pair selection: frames whose ground footprints overlap, from the telemetry that frames.json carries
// per frame (KLV / DJI SRT: sensor position, attitude, field of view, optionally the frame centre on the
// ground). A footprint is approximated by a disc on the ground around the point the optical axis hits: its
// radius is the larger half-extent of the view on flat ground (across: range·tan(hfov/2); along an oblique
// view: range·tan(vfov/2)/sin(depression)). Positions are in a local east-north frame in metres.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

#include "fmv3d/features/pairs.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::features {

struct Footprint {
  bool valid = false;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // metres east, north of the first valid frame's sensor
  double radius = 0;                                 // metres
  std::string why_invalid;                           // when !valid: which telemetry field is missing
};

// One footprint per frame of the index (same order). A frame needs sensor latitude/longitude and an altitude;
// the field of view comes from the telemetry or else from the camera prior; pointing from the frame centre
// coordinates, else gimbal / sensor angles, else nadir is assumed.
std::vector<Footprint> FootprintsFromTelemetry(const io::FramesIndex& index);

// Pairs (0-based, first < second) of valid footprints whose centres are closer than
// overlap_factor · (r_i + r_j); each frame keeps at most max_neighbours of them (nearest first, the union
// over both ends is returned).
std::vector<ImagePair> SpatialPairs(const std::vector<Footprint>& footprints, double overlap_factor,
                                    int max_neighbours);

// kAuto's choice for photo sets: true when every frame is its own still (each frame its own source file, as
// for a folder of photos, not frames of a video), every frame has a valid footprint (GPS position and an
// altitude), and there are more frames than exhaustive matching is chosen for. A survey's GPS then names the
// overlapping pairs directly, across flight lines too, at a fraction of exhaustive matching's cost.
bool PreferSpatialPairs(const io::FramesIndex& index, const std::vector<Footprint>& footprints,
                        const PairOptions& options);

}  // namespace fmv3d::features
