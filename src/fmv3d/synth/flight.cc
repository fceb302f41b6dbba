#include "fmv3d/synth/flight.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "fmv3d/core/error.h"

namespace fmv3d::synth {
namespace {

// Portable standard normal from a 64-bit Mersenne Twister (std::normal_distribution differs between
// standard libraries, and the flight must be the same everywhere for a seed).
struct Normal {
  std::mt19937_64 rng;
  explicit Normal(uint64_t seed) : rng(seed * 0x9E3779B97F4A7C15ull + 0x5DEECE66Dull) {}
  double operator()() {
    const double u1 = (static_cast<double>(rng() >> 11) + 0.5) / 9007199254740992.0;
    const double u2 = static_cast<double>(rng() >> 11) / 9007199254740992.0;
    return std::sqrt(-2 * std::log(u1)) * std::cos(2 * M_PI * u2);
  }
};

}  // namespace

const char* FlightPathName(FlightPath path) {
  switch (path) {
    case FlightPath::kOrbit:
      return "orbit";
    case FlightPath::kGrid:
      return "grid";
    case FlightPath::kPass:
      return "pass";
    case FlightPath::kOblique:
      return "oblique";
  }
  return "orbit";
}

FlightPath ParseFlightPath(const std::string& name) {
  for (FlightPath p : {FlightPath::kOrbit, FlightPath::kGrid, FlightPath::kPass, FlightPath::kOblique})
    if (name == FlightPathName(p)) return p;
  throw Error("flight: unknown path '" + name + "' (expected orbit, grid, pass or oblique)");
}

void FlightOptions::Check() const {
  if (frames < 1) throw Error("flight: --frames must be at least 1");
  if (!(altitude_swing >= 0)) throw Error("flight: --altitude-swing must be >= 0");
  if (altitude && !std::isfinite(*altitude)) throw Error("flight: altitude must be finite");
  if (radius && !(*radius > 0)) throw Error("flight: radius must be positive");
  if (!(jitter_deg >= 0 && jitter_deg < 20)) throw Error("flight: jitter must be in [0, 20) degrees");
  if (!(position_jitter >= 0)) throw Error("flight: position jitter must be >= 0");
  if (grid_overlap && !(grid_overlap->first >= 0 && grid_overlap->first <= 0.95 && grid_overlap->second >= 0 &&
                        grid_overlap->second <= 0.95))
    throw Error("flight: grid overlaps must be in [0, 95] percent");
}

FlightGeometry ResolveFlight(const Scene& scene, const core::Camera& camera, const FlightOptions& o) {
  FlightGeometry g;
  g.look_at = o.look_at ? *o.look_at : scene.target;
  const double r = scene.interest_radius;
  // Distance at which the interest radius fills ~70% of the shorter image half-size.
  const double half_fov = std::atan(0.5 * std::min(camera.width / camera.fx(), camera.height / camera.fy()));
  const double dist = r / std::tan(half_fov) / 0.7 + r;
  const double ground = scene.ground_height ? scene.ground_height(g.look_at.x(), g.look_at.y()) : 0.0;
  if (o.path == FlightPath::kOrbit) {
    const double elevation = 40 * M_PI / 180;
    g.radius = o.radius ? *o.radius : dist * std::cos(elevation);
    g.altitude = o.altitude ? *o.altitude : g.look_at.z() + dist * std::sin(elevation);
  } else if (o.path == FlightPath::kGrid) {
    g.radius = o.radius ? *o.radius : r * 1.2;
    g.altitude = o.altitude ? *o.altitude : ground + std::max(dist * 0.8, 2.0 * scene.characteristic_length);
  } else if (o.path == FlightPath::kOblique) {
    g.radius = o.radius ? *o.radius : r;
    g.altitude = o.altitude ? *o.altitude : g.look_at.z() + 0.4 * r;
  } else {
    g.radius = o.radius ? *o.radius : dist * std::cos(M_PI / 4);
    g.altitude = o.altitude ? *o.altitude : g.look_at.z() + dist * std::sin(M_PI / 4);
  }
  return g;
}

std::vector<core::Pose> MakeFlight(const Scene& scene, const core::Camera& camera, const FlightOptions& o) {
  o.Check();
  const FlightGeometry g = ResolveFlight(scene, camera, o);
  const int n = o.frames;
  std::vector<Eigen::Vector3d> centres(n);
  std::vector<Eigen::Matrix3d> rotations(n);  // world-to-camera
  if (o.path == FlightPath::kOrbit) {
    for (int k = 0; k < n; ++k) {
      const double a = 2 * M_PI * k / n - M_PI / 2;  // start south of the target, counter-clockwise
      centres[k] = {g.look_at.x() + g.radius * std::cos(a), g.look_at.y() + g.radius * std::sin(a),
                    g.altitude + o.altitude_swing * std::sin(2 * a)};
      rotations[k] = core::Pose::LookAt(centres[k], g.look_at).R();
    }
  } else if (o.path == FlightPath::kGrid && o.grid_overlap) {
    // Footprint on the ground at the look-at height: across track (image x) and along track (image y).
    const double h = std::max(1.0, g.altitude - g.look_at.z());
    const double step_across = (1 - o.grid_overlap->second) * h * camera.width / camera.fx();
    const double step_along = (1 - o.grid_overlap->first) * h * camera.height / camera.fy();
    int strips = 1;
    double best = std::numeric_limits<double>::infinity();
    for (int s = 1; s <= n; ++s) {
      const int per_strip = (n + s - 1) / s;
      const double aspect =
          std::abs(std::log(((s - 1) * step_across + step_across) / ((per_strip - 1) * step_along + step_along)));
      if (aspect < best) best = aspect, strips = s;
    }
    int k = 0;
    for (int s = 0; s < strips; ++s) {
      const int count = n / strips + (s < n % strips ? 1 : 0);
      const double x = g.look_at.x() + (s - 0.5 * (strips - 1)) * step_across;
      const bool north = s % 2 == 0;
      for (int i = 0; i < count; ++i, ++k) {
        const double y = g.look_at.y() + (north ? 1 : -1) * (i - 0.5 * (count - 1)) * step_along;
        centres[k] = {x, y, g.altitude};
        const Eigen::Vector3d zc(0, 0, -1), yc(0, north ? -1 : 1, 0);
        Eigen::Matrix3d Rwc;
        Rwc << yc.cross(zc), yc, zc;
        rotations[k] = Rwc.transpose();
      }
    }
  } else if (o.path == FlightPath::kGrid) {
    // Nadir footprint at this height above the look-at point decides the strip spacing (65% side overlap).
    const double h = std::max(1.0, g.altitude - g.look_at.z());
    const double across = h * camera.width / camera.fx();
    const double spacing = 0.35 * across;
    const double side = 2 * g.radius;
    int strips = std::max(1, static_cast<int>(std::ceil(side / spacing)) + 1);
    strips = std::min(strips, std::max(1, n / 3));
    const double sp = strips > 1 ? side / (strips - 1) : 0;
    int k = 0;
    for (int s = 0; s < strips; ++s) {
      const int count = n / strips + (s < n % strips ? 1 : 0);
      const double x = g.look_at.x() - (strips > 1 ? g.radius : 0) + s * sp;
      const bool north = s % 2 == 0;
      for (int i = 0; i < count; ++i, ++k) {
        const double f = count > 1 ? static_cast<double>(i) / (count - 1) : 0.5;
        const double y = g.look_at.y() + (north ? -1 : 1) * g.radius * (1 - 2 * f);
        centres[k] = {x, y, g.altitude};
        // Camera z down, image "up" (−y_cam) along the flight direction, x_cam across track.
        const Eigen::Vector3d zc(0, 0, -1), yc(0, north ? -1 : 1, 0);
        Eigen::Matrix3d Rwc;  // columns: camera axes in world
        Rwc << yc.cross(zc), yc, zc;
        rotations[k] = Rwc.transpose();
      }
    }
  } else if (o.path == FlightPath::kOblique) {
    // Fly along x, `radius` south of the target, looking north 12° below the horizontal: the horizon is in
    // the upper part of the frame, the land runs from the near ground to the far distance.
    const double length = 2 * g.radius, depression = 12 * M_PI / 180;
    const Eigen::Vector3d ahead(0, std::cos(depression), -std::sin(depression));
    for (int k = 0; k < n; ++k) {
      const double f = n > 1 ? static_cast<double>(k) / (n - 1) : 0.5;
      centres[k] = {g.look_at.x() - length / 2 + length * f, g.look_at.y() - g.radius, g.altitude};
      rotations[k] = core::Pose::LookAt(centres[k], centres[k] + ahead).R();
    }
  } else {  // pass: fly along x on the south side of the target, looking north-down at the target line
    const double length = 2 * std::max(scene.interest_radius, 0.5 * g.radius);
    for (int k = 0; k < n; ++k) {
      const double f = n > 1 ? static_cast<double>(k) / (n - 1) : 0.5;
      const double x = g.look_at.x() - length / 2 + length * f;
      centres[k] = {x, g.look_at.y() - g.radius, g.altitude};
      rotations[k] = core::Pose::LookAt(centres[k], {x, g.look_at.y(), g.look_at.z()}).R();
    }
  }
  // Gimbal-like jitter: a slow wander (sum of two random sinusoids per axis) plus frame-to-frame shake.
  Normal normal(o.seed);
  const double sigma = o.jitter_deg * M_PI / 180;
  double amp[3][2], freq[3][2], phase[3][2];
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 2; ++j) {
      amp[a][j] = sigma * 0.9 * std::abs(normal());
      freq[a][j] = 2 * M_PI * (0.01 + 0.05 * std::abs(normal())) * (j + 1);
      phase[a][j] = 2 * M_PI * std::abs(normal());
    }
  std::vector<core::Pose> poses(n);
  for (int k = 0; k < n; ++k) {
    Eigen::Vector3d rv;
    for (int a = 0; a < 3; ++a) {
      rv[a] = 0.4 * sigma * normal();
      for (int j = 0; j < 2; ++j) rv[a] += amp[a][j] * std::sin(freq[a][j] * k + phase[a][j]);
    }
    const Eigen::Vector3d dp(normal(), normal(), normal());
    const Eigen::Matrix3d jitter =
        Eigen::AngleAxisd(rv.norm(), rv.norm() > 0 ? rv.normalized() : Eigen::Vector3d::UnitX()).toRotationMatrix();
    // Jitter is applied in the camera frame (the gimbal wobbles around the commanded attitude).
    // Position jitter is specified for a 100 m stand-off and scales with the distance to the target, so
    // small scenes (the chessboard) are not shaken out of view.
    const double scale = std::min(1.0, (centres[k] - g.look_at).norm() / 100.0);
    poses[k] = core::Pose::FromRotationAndCentre(jitter * rotations[k], centres[k] + o.position_jitter * scale * dp);
  }
  return poses;
}

}  // namespace fmv3d::synth
