// Oriented point clouds sampled from a known surface, and the accuracy of a reconstructed mesh against it:
// the yardstick for the surface and texture stages on synthetic flights, independent of the dense stage.
//
// SampleOrientedCloud draws points uniformly over a true mesh (geometry::MeshDistance::SampleSurface), keeps
// those that at least `min_views` cameras see (depth test against the mesh rendered from each camera, facing
// the camera), and gives each the face's normal, the colour a camera renders there and the list of image ids
// that see it — what an ideal dense stage would produce — then perturbs positions and normals with Gaussian
// noise and replaces a share of points by outliers, as a real one does.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geometry/mesh_distance.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"
#include "fmv3d/surface/colored_mesh.h"

namespace fmv3d::surface {

struct SyntheticCloudOptions {
  double spacing = 0.1;         // distance between samples, metres
  int min_views = 2;            // a point must be seen by this many cameras
  double position_noise = 0;    // Gaussian, metres (1 sigma per axis)
  double normal_noise_deg = 0;  // Gaussian tilt of the normals, degrees
  double outlier_share = 0;     // share of points moved by up to ±outlier_range along a random direction
  double outlier_range = 1.0;   // metres
  double max_distance = 0;      // ignore surface farther than this from every camera (0 = no limit)
  Eigen::AlignedBox3d region;   // only faces overlapping this box are sampled (empty box: all)
  uint64_t seed = 1;
  void Check() const;
};

struct SyntheticCloud {
  io::OrientedPointCloud cloud;               // noisy, with outliers
  std::vector<Eigen::Vector3d> seen_surface;  // the noise-free samples that were kept (the "seen" truth)
};

SyntheticCloud SampleOrientedCloud(const io::TexturedMesh& truth, const core::Reconstruction& cameras,
                                   const SyntheticCloudOptions& options);

// A workspace for the surface stages from `fmv3d synth` output in synth_dir, as if the earlier stages had
// run perfectly: frames/ copied, truth/ (less the `held_out` image names) as sparse/, and dense/fused.ply
// sampled from scene.obj with SampleOrientedCloud (cameras: the kept images). Returns the cloud and the seen
// true surface. Throws fmv3d::Error when synth_dir lacks frames/, truth/ or scene.obj.
SyntheticCloud PrepareSyntheticWorkspace(const std::filesystem::path& synth_dir, const std::filesystem::path& workspace,
                                         const SyntheticCloudOptions& options,
                                         const std::vector<std::string>& held_out = {});

struct MeshAccuracy {
  size_t samples = 0;  // points sampled on the reconstructed mesh
  double rms = 0;      // RMS distance of those samples to the true surface
  double mean = 0, median = 0, p90 = 0, max = 0;
  double completeness = 0;  // share of the seen true surface within `tolerance` of the reconstruction
  double tolerance = 0;
};

// Accuracy: the reconstructed surface sampled every `spacing` and measured against `truth`; completeness:
// the share of `seen_surface` points that have reconstructed surface within `tolerance`.
MeshAccuracy EvaluateMesh(const ColoredMesh& mesh, const geometry::MeshDistance& truth,
                          const std::vector<Eigen::Vector3d>& seen_surface, double spacing, double tolerance);

}  // namespace fmv3d::surface
