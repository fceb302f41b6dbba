// The roll about a nearly straight track. Camera positions on a line fix the similarity's rotation only up to a
// turn about that line; the model's ground plane, which must be level in ENU, fixes the rest.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "fmv3d/core/pose.h"

namespace fmv3d::geo {

enum class RollSource {
  kCameraPositions,  // the positions spread sideways beyond their noise: they fix the whole rotation
  kGroundPlane,      // a nearly straight track: the roll about it from the level ground plane
};
const char* RollSourceName(RollSource s);  // for georef.json

// Unit normal of the ground plane of `points`, pointing towards `above`: the plane with the most points within 1%
// of the points' median distance from their centroid (deterministic RANSAC over 3-point samples,
// geometry/robust.h), refitted to those points by their smallest principal axis. A plain fit to every point is
// tilted by walls and roofs (a synthetic pass by a building: +5 m of DSM bias). nullopt with fewer than 10 points.
std::optional<Eigen::Vector3d> GroundNormal(const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& above);

// Rotates `sim` about the (ENU) line through `centre` along `axis` so that the model's ground normal maps as close
// to +z (up) as possible.
core::Sim3 LevelAboutAxis(const core::Sim3& sim, const Eigen::Vector3d& axis, const Eigen::Vector3d& centre,
                          const Eigen::Vector3d& model_normal);

struct RollLevelling {
  core::Sim3 sim;  // `sim` levelled about the track, or unchanged
  RollSource source = RollSource::kCameraPositions;
};
// When the ENU positions `dst` have no sideways spread beyond the noise (second principal σ below max(sigma, 5%
// of the first)), levels `sim` about their principal line from the ground plane of the model points (`src` are
// the model camera centres: the ground normal points towards them). Throws fmv3d::Error when the track is
// straight and the model has too few points to find the ground.
RollLevelling LevelRollFromGround(const core::Sim3& sim, const std::vector<Eigen::Vector3d>& src,
                                  const std::vector<Eigen::Vector3d>& dst, double sigma,
                                  const std::vector<Eigen::Vector3d>& model_points);

}  // namespace fmv3d::geo
