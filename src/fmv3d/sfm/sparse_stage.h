// The `fmv3d sparse WS` stage: frames.json + features/*.feat + matches/matches.bin → incremental SfM →
//   WS/sparse/            the largest model as a COLMAP text model (+ sparse.ply, coloured points)
//   WS/sparse/1, 2, ...   further disconnected models, largest first
// Images the mapper left out of the largest model are then retried against it (relocalise.h), and then through
// the operator's tie points (WS/matches/manual.json from `match`, sfm/manual_registration.h), whose
// observations weigh manual.options.weight times an automatic one in every bundle adjustment.
//   WS/report/sparse.json registered / total (with the reason for every image left out), points, mean track
//                         length, mean reprojection error, cameras, time per stage.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/reconstruction.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/sfm/incremental_mapper.h"
#include "fmv3d/sfm/manual_registration.h"
#include "fmv3d/sfm/relocalise.h"

namespace fmv3d::sfm {

struct SparseStageOptions {
  MapperOptions mapper;
  // After the mapper: images outside the largest model retried against it (relocalise.h).
  struct {
    bool enabled = true;
    RelocaliseOptions options;
  } relocalise;
  // The operator's tie points (docs/manual-inputs.md): weighted, and registering left-out frames.
  struct {
    bool enabled = true;
    ManualRegistrationOptions options;
  } manual;
  // Focal prior for every camera, overriding frames.json's (e.g. from a lens spec or the telemetry's horizontal
  // field of view): focal in pixels, or the horizontal FOV in degrees (f = w / 2 / tan(hfov / 2)). 0 = unset.
  // Such a prior counts as known (no scan); with mapper.fix_known_focal it also stays fixed in BA.
  double focal_px = 0, hfov_deg = 0;
  // `--max-memory MB`: the stage holds its whole model (sparse_memory.h), so the budget is not a window it sizes:
  // when the bound from the matches exceeds it, part of each image's matched keypoints (the least connected,
  // spread over the image) is left out of mapping until it fits (a warning says so, or that it cannot fit), and
  // report/sparse.json's "memory" states it.
  double max_memory_mb = 2048;
  void Check() const;
};

// Returns the summary that is also written to WS/report/sparse.json. Throws fmv3d::Error naming the missing
// or malformed input file; when nothing can be reconstructed it still writes the report (with reasons), and
// then throws so the CLI exits non-zero.
nlohmann::json RunSparseStage(const core::Workspace& workspace, const SparseStageOptions& options);

// Binary little-endian PLY of the model's points: x y z (float), red green blue (uchar).
void WritePointsPly(const core::Reconstruction& rec, const std::filesystem::path& path);

}  // namespace fmv3d::sfm
