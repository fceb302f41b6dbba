// `fmv3d reconstruct INPUT... -o WS`: the whole chain frames → features → match → sparse → dense → mesh →
// texture (→ georef → dsm → ortho when the frames carry telemetry) in one workspace (DESIGN.md "The data flow"),
// resumable (stage_runner.h), with WS/project.json (inputs, options, versions) and WS/report/report.json + report.html
// at the end.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/calib/priors.h"
#include "fmv3d/features/match_stage.h"
#include "fmv3d/features/sift.h"
#include "fmv3d/geo/dsm.h"
#include "fmv3d/geo/georef.h"
#include "fmv3d/ingest/frames.h"
#include "fmv3d/mvs/dense_stage.h"
#include "fmv3d/pipeline/stage_runner.h"
#include "fmv3d/sfm/sparse_stage.h"
#include "fmv3d/surface/mesh_stage.h"
#include "fmv3d/surface/texture_stage.h"

namespace fmv3d::pipeline {

struct ReconstructOptions {
  std::vector<std::filesystem::path> inputs;
  std::filesystem::path workspace;
  ingest::IngestOptions frames;  // .workspace and .prior are filled from the fields above / below
  calib::PriorOptions prior;
  features::SiftOptions sift;
  features::MatchStageOptions match;
  sfm::SparseStageOptions sparse;
  mvs::DenseStageOptions dense;
  surface::MeshStageOptions mesh;
  surface::TextureStageOptions texture;
  geo::GeorefOptions georef;  // georef / dsm / ortho run only when the frames carry telemetry
  geo::DsmOptions dsm;
  RunnerOptions runner;  // --from / --until
  bool report = true;    // write report/report.html (renders take a few seconds)
  bool fast = false;     // set by ApplyFastPreset (recorded in project.json)
  // `--fast`: the video-speed preset (bench/RESULTS.md has its time and accuracy next to the defaults).
  // 5000 SIFT features (not 8000), sequential pairs with the next 5 frames (not 10); dense as the demo runs it — half
  // the default working size (480 px), 4 sources, 3 rounds, no geometric pass — with depth maps only for the reference
  // views that cover every sparse point 8 times (video keyframes see each surface point ~20-30 times; the rest stay
  // stereo sources); Poisson one octree level coarser than the point density allows; texture colours from the same kind
  // of cover.
  void ApplyFastPreset();
  // `--max-memory MB`: the budget of every stage that sizes its working window (features' images in flight and
  // tiles, matching's descriptor cache, dense's view cache and fusion window, mesh's Poisson depth, texture's decoded
  // frames); sparse, which holds its whole model, maps fewer observations when its bound exceeds it
  // (sfm/sparse_memory.h); the peaks are measured in bench/results/scale11.md.
  void SetMaxMemory(double mb);
  // Throws fmv3d::Error naming the bad option (no inputs, missing file, stage options).
  void Check() const;
};

// The stage list for a workspace (exposed for tests and for `fmv3d demo`).
std::vector<Stage> ReconstructStages(const ReconstructOptions& options);

// Runs the stages and writes the report; returns report.json's content (null when options.report is off).
// `stage_results` (optional) receives each stage's wall and CPU time.
nlohmann::json RunReconstruct(const ReconstructOptions& options, std::vector<StageResult>* stage_results = nullptr);

}  // namespace fmv3d::pipeline
