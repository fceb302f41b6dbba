// The CAD model coloured by a comparison's errors (`fmv3d compare` → OUTDIR/cad_error.ply), for viewers: the
// console's 3D view, MeshLab, CloudCompare. A CAD model has few, large faces (a building: 16 triangles), so its
// surface is first subdivided until no edge is longer than max_edge; every vertex of that mesh then carries the
// mean signed distance of the measured reconstruction points within `radius` of it (+ outside the CAD, − inside;
// NaN where there is none: a hole of the reconstruction, or surface below the ground cut), and that value as a
// colour on a diverging scale: blue (−scale or less) → white (0) → red (+scale or more), grey for NaN.
//
// PLY written (binary little-endian), in the CAD frame:
//   element vertex N: float x y z, uchar red green blue, float error   (error: percent of H, NaN when unknown)
//   element face M:   list uchar int vertex_indices
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::align {

struct ErrorMeshOptions {
  double max_edge = 0;               // CAD units, > 0: subdivision until every edge is at most this long ...
  size_t max_triangles = 1'000'000;  // ... unless that makes more triangles than this (then edges grow)
  double radius = 0;                 // CAD units, > 0: points within it of a vertex make its error
  double scale = 0;                  // fraction of H, > 0: the colour saturates at ± this
  double length = 0;                 // H, > 0
  void Check() const;                // throws fmv3d::Error naming the bad field
};

struct ErrorMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<float> error;      // per vertex: signed distance, fraction of H; NaN when no point is near
  std::vector<io::Rgb8> colors;  // per vertex: `error` on the diverging scale
  double covered_fraction = 0;   // vertices with a known error
};

// The diverging colour of a signed value (fraction of the scale; NaN → grey).
io::Rgb8 DivergingColor(double t);

// `points` and `signed_error` (fraction of H, one per point) in the CAD frame. Throws fmv3d::Error when the
// sizes differ or the options are invalid.
ErrorMesh BuildErrorMesh(const io::TexturedMesh& cad, const std::vector<Eigen::Vector3d>& points,
                         const std::vector<double>& signed_error, const ErrorMeshOptions& options);

// Writes the PLY above (errors in percent of H). Throws fmv3d::Error when the file cannot be written.
void WriteErrorMeshPly(const ErrorMesh& mesh, const std::filesystem::path& path);

}  // namespace fmv3d::align
