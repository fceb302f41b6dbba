// Synthetic worlds: textured terrain plus CAD-like buildings, in metres, z up, ground around z = 0.
//
// Scenes (fixed worlds: the same geometry and textures on every run, whatever the flight's seed):
//   building  one building, 20 m (x) × 12 m (y) footprint centred at the origin, walls to 24 m, a gable
//             roof whose ridge (along x) is at 30 m; on gently rolling, flattened ground. The same building is
//             shipped as data/scenes/building.obj (textures are generated at run time).
//   town      several buildings (flat and pitched roofs, 8–42 m tall) on hilly terrain.
//   terrain   a height field with hills and a ridge, no buildings.
//   sand      low-texture dunes (relief ~25 m) of sand with dry grass and ponds, faint contrast: the hard case
//             for feature detection in nadir surveys.
//   board     a flat 9×6-inner-corner chessboard (squares of `board_square` metres) lying on z = 0, for
//             calibration tests.
// characteristic_length is the tallest building's height above its ground (for `terrain`: the relief,
// max − min height; for `board`: the board's width).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include "fmv3d/io/mesh.h"

namespace fmv3d::synth {

struct BuildingSpec {
  std::string name = "building";
  double width = 20, depth = 12;                   // footprint along the building's x and y axes, metres
  double eave_height = 24;                         // top of the walls above the base
  double ridge_height = 30;                        // roof ridge above the base (= eave_height: flat roof)
  Eigen::Vector3d base = Eigen::Vector3d::Zero();  // centre of the footprint at ground level
  double heading_deg = 0;                          // rotation of the building's x axis from world x (counter-clockwise)
  double sink = 0;                                 // walls extend this far below the base (into sloping ground)
  double floor_height = 3;
  uint64_t style_seed = 1;
};

// A closed, outward-wound building mesh with façade and roof textures (texels_per_metre ≤ 0: no textures,
// materials keep their texture_file names, as in the shipped OBJ).
io::TexturedMesh MakeBuilding(const BuildingSpec& spec, double texels_per_metre);

struct SceneOptions {
  double detail = 1.0;        // texture resolution multiplier (e.g. 0.25 for fast tests)
  double board_square = 0.1;  // chessboard square size, metres
  void Check() const;
};

struct Scene {
  std::string name;
  io::TexturedMesh mesh;
  std::vector<BuildingSpec> buildings;
  std::function<double(double, double)> ground_height;  // terrain height at (x, y)
  Eigen::AlignedBox2d ground_extent;                    // horizontal extent of the terrain mesh
  Eigen::Vector3d target = Eigen::Vector3d::Zero();     // centre of interest (default look-at)
  double interest_radius = 30;                          // horizontal radius of the interesting part
  double characteristic_length = 0;
  // The modelled area (terrain tile and buildings). The mesh also holds a coarse far-ground ring around
  // it (material "far_ground", 0.3 m lower, meeting the tile's border without a step) so oblique views see land,
  // not the edge of the world.
  Eigen::AlignedBox3d bounds;

  Eigen::AlignedBox3d Bounds() const { return bounds; }
};

enum class SceneKind { kBuilding, kTown, kTerrain, kBoard, kSand };
const std::vector<SceneKind>& SceneKinds();
// The spelling of the command line and truth/truth.json: "building", "town", "terrain", "board", "sand".
const char* SceneName(SceneKind kind);
// Throws fmv3d::Error naming the accepted spellings.
SceneKind ParseScene(const std::string& name);

Scene MakeScene(SceneKind kind, const SceneOptions& options = {});

}  // namespace fmv3d::synth
