// CAD comparison (`fmv3d compare`): how far a reconstruction is from the design model.
//
//   1. Align the reconstruction (point cloud, or a mesh's vertices) to the CAD frame: coarse by a given
//      similarity (e.g. sfm::EvaluateSparse(sparse, truth).alignment, or a georeference), else by global
//      registration (global_registration.h); then refined by the scaled point-to-plane ICP (icp.h) against
//      points sampled on the CAD surface, unless disabled.
//   2. Crop: points outside the CAD's bounding box grown by crop_margin·H (neighbours, sky noise), and points
//      lower than ground_cut·H above the CAD's lowest point (the ground it stands on: the CAD frame is z-up,
//      as every fmv3d world) are not part of the object; they are counted, not measured. CAD surface below
//      the ground cut is likewise left out of completeness (nobody sees the underside of a building).
//   3. Errors per point: e = p − closest point of the CAD surface (geometry/mesh_distance.h), its X, Y, Z
//      components and the signed distance (+ outside, − inside), all as fractions of H. Per quantity:
//      mean, standard deviation, RMS of the signed values, and 50/90/99th percentiles of the absolute values.
//   4. Completeness: the share of CAD surface samples with a reconstructed point within
//      completeness_threshold·H (for a mesh: a point of its surface, i.e. its vertices and points sampled
//      on its faces every sample_spacing·H, so a coarse but faithful mesh is not counted as holes); with `cameras` (a
//      COLMAP model in the CAD frame) only samples that at least min_views cameras see (depth test against the CAD
//      rendered by render::Renderer) count.
//   5. Outputs in output_dir: compare.json (everything below), cad_error.ply (the CAD coloured by the error,
//      error_mesh.h), histograms.png (X, Y, Z error histograms in
//      one plot), top.png and side.png (the CAD with the points coloured by error), compare.html.
//
// The transform for a reconstruction made from a synthetic flight is the sparse model's alignment to the
// truth: `sfm::EvaluateSparse(ReadColmapText(ws/sparse), LoadTruth(synth/truth)).alignment` maps the model
// into the truth frame, which is the CAD frame of synth's scene.obj / data/scenes/building.obj. The ICP then
// removes what the camera-centre alignment leaves (a few 0.01% of the scene), so the figures measure shape.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "fmv3d/align/global_registration.h"
#include "fmv3d/align/icp.h"
#include "fmv3d/align/sim3_json.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::align {

struct CompareOptions {
  std::filesystem::path reconstruction;  // PLY (points or mesh: vertices are used)
  std::filesystem::path cad;             // OBJ
  double length = 0;                     // characteristic length H in CAD units (e.g. building height), > 0
  std::filesystem::path output_dir;      // empty: write nothing (library use)
  std::optional<core::Sim3> transform;   // reconstruction → CAD; absent: global registration
  bool icp = true;                       // refine by scaled ICP
  IcpOptions icp_options = DefaultIcpOptions();
  GlobalRegistrationOptions global_options;
  std::filesystem::path cameras;         // optional COLMAP model in the CAD frame (visibility for completeness)
  double crop_margin = 0.05;             // × H around the CAD's bounding box
  double ground_cut = 0.03;              // × H above the CAD's lowest z: below is ground, not measured (0 = off)
  double completeness_threshold = 0.01;  // × H
  double sample_spacing = 0.005;         // × H, CAD surface samples for completeness and ICP
  int min_views = 2;                     // cameras that must see a sample for it to count (with `cameras`)
  int max_render_size = 800;             // visibility depth maps are rendered at most this wide (pixels)
  void Check() const;                    // throws fmv3d::Error naming the bad field
  static IcpOptions DefaultIcpOptions();
};

struct ErrorStats {                   // fractions of H
  double mean = 0, std = 0, rms = 0;  // of the signed values
  double p50 = 0, p90 = 0, p99 = 0;   // of the absolute values
  nlohmann::json ToJson() const;      // in percent of H
};

struct CompareResult {
  core::Sim3 transform;  // reconstruction → CAD, final
  std::string coarse;    // "transform" | "global:pca" | "global:fpfh"
  std::optional<IcpResult> icp;
  size_t points_total = 0, points_measured = 0, points_cropped = 0;
  ErrorStats x, y, z, total;             // total: signed distance
  double completeness = 0;               // share of counted CAD samples with a point within the threshold
  double completeness_threshold = 0;     // fraction of H
  size_t surface_samples = 0;            // counted samples
  bool completeness_seen_only = false;   // samples restricted to those seen by ≥ min_views cameras
  bool completeness_from_faces = false;  // the reconstruction's faces were sampled for completeness
  double length = 0;
  nlohmann::json ToJson() const;
};

// The whole comparison from files (see the header comment); writes the outputs when output_dir is set. A PLY
// with faces is a mesh: its vertices are measured and its surface counts for completeness.
// Throws fmv3d::Error for unreadable inputs, an empty reconstruction, no point within the crop box, or a
// failed alignment.
CompareResult CompareToCad(const CompareOptions& options);

// The same on data in memory (options' paths other than cameras/output_dir are ignored). `triangles`
// (optional) are faces over the reconstruction's positions.
CompareResult CompareToCad(const io::OrientedPointCloud& reconstruction, const io::TexturedMesh& cad,
                           const CompareOptions& options, const std::vector<Eigen::Vector3i>& triangles = {});

}  // namespace fmv3d::align
