#include "fmv3d/pipeline/reconstruct.h"

#include <spdlog/spdlog.h>

#include <algorithm>

#include "fmv3d/core/error.h"
#include "fmv3d/core/file_lock.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/progress_log.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/pipeline/report.h"
#include "fmv3d/pipeline/tiles_stage.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

void ReconstructOptions::Check() const {
  if (inputs.empty()) throw Error("reconstruct: no input (give images, folders or videos)");
  for (const auto& in : inputs)
    if (!fs::exists(in)) throw Error(in.string() + ": no such file or folder");
  if (workspace.empty()) throw Error("reconstruct: no workspace folder (-o WS)");
  match.Check();
  sparse.Check();
  dense.Check();
  mesh.Check();
  texture.Check();
  georef.Check();
  dsm.Check();
}

void ReconstructOptions::ApplyFastPreset() {
  fast = true;
  // 5000 features and 5 sequential neighbours: matching 33 -> 13 s and sparse 54 -> 39 s on the 60 s clip, for
  // cameras 0.0060% -> 0.0082% of the extent (bench/RESULTS.md).
  sift.max_features = 5000;
  match.pairs.overlap = 5;
  dense.max_size = 480;
  dense.max_sources = 4;
  dense.patch_match.iterations = 3;
  dense.geometric = false;
  dense.references.coverage = 8;
  mesh.poisson.cell_to_spacing = 4;  // one octree level coarser: 1/3 of Poisson's time, same error vs CAD
  texture.view_coverage = 8;
}

void ReconstructOptions::SetMaxMemory(double mb) {
  if (!(mb > 0)) throw Error("reconstruct: --max-memory must be > 0 MB");
  sift.max_memory_mb = mb;
  match.max_memory_mb = mb;
  sparse.max_memory_mb = mb;
  dense.max_memory_mb = mb;
  mesh.poisson.max_memory_mb = mb;
  texture.max_memory_mb = mb;
}

std::vector<Stage> ReconstructStages(const ReconstructOptions& o) {
  const core::Workspace ws(o.workspace);
  const fs::path& root = ws.root();
  std::vector<Stage> stages;
  stages.push_back({"frames",
                    [o] {
                      // Every input file (folders expanded) is an input of the frames stage.
                      return ingest::ExpandInputs(o.inputs);
                    },
                    ws.frames_json(),
                    [o, root] {
                      ingest::IngestOptions io_opt = o.frames;
                      io_opt.workspace = root;
                      const calib::PriorChooser chooser(o.prior, calib::SensorDatabase::LoadDefault());
                      io_opt.prior = chooser.AsFunction();
                      const io::FramesIndex index = ingest::IngestFrames(o.inputs, io_opt);
                      return nlohmann::json{{"frames", index.frames.size()}, {"cameras", index.cameras.size()}};
                    }});
  stages.push_back({"features", [ws] { return std::vector<fs::path>{ws.frames_json()}; },
                    ws.features_dir() / "features.json",
                    [o, root] {
                      const auto s = features::RunFeaturesStage(root, o.sift);
                      return nlohmann::json{{"images", s.images},
                                            {"keypoints", s.total_keypoints},
                                            {"min_keypoints", s.min_keypoints},
                                            {"max_keypoints", s.max_keypoints},
                                            {"memory",
                                             {{"max_memory_mb", o.sift.max_memory_mb},
                                              {"estimated_image_mb", s.max_image_bytes / 1048576.0},
                                              {"workers", s.workers},
                                              {"tiled_images", s.tiled_images},
                                              {"max_tiles", s.max_tiles}}}};
                    }});
  stages.push_back({"match", [ws] { return std::vector<fs::path>{ws.features_dir() / "features.json"}; },
                    features::MatchesSummaryPath(ws.matches_dir()),
                    [o, root] {
                      const auto s = features::RunMatchStage(root, o.match);
                      return nlohmann::json{{"pairs_tried", s.pairs_tried}, {"pairs_verified", s.pairs_verified}};
                    }});
  stages.push_back({"sparse", [ws] { return std::vector<fs::path>{features::MatchesSummaryPath(ws.matches_dir())}; },
                    ws.sparse_dir() / "images.txt", [o, root] { return sfm::RunSparseStage(root, o.sparse); }});
  // Terrain products need telemetry (KLV, DJI SRT, EXIF GPS): without it these stages say so and write
  // nothing (their markers stay absent, so adding telemetry later and re-running makes them).
  // The products after georef also need its georef.json.
  enum class Needs { kTelemetry, kGeoreference };
  auto with_telemetry = [ws](const char* stage, Needs needs, const std::function<nlohmann::json()>& run) {
    return [ws, stage, needs, run] {
      const io::FramesIndex index = io::ReadFramesIndex(ws.frames_json());
      const bool any = std::any_of(index.frames.begin(), index.frames.end(),
                                   [](const io::FrameRecord& f) { return f.telemetry.has_value(); });
      if (!any && !fs::exists(ws.manual_dir() / "gcp_list.txt")) {
        spdlog::info("{}: no telemetry in frames.json (KLV, SRT or GPS) nor GCPs, no georeferenced products", stage);
        return nlohmann::json{{"skipped", "no telemetry"}};
      }
      if (needs == Needs::kGeoreference && !fs::exists(ws.georef_json())) {
        spdlog::info("{}: no georeference (see the georef stage's warning), skipped", stage);
        return nlohmann::json{{"skipped", "no georeference"}};
      }
      return run();
    };
  };
  // georef runs before dense: when the image-only model disagrees with the flight it replaces WS/sparse with the
  // telemetry-initialised model (geo/georef.h), which the dense cloud, mesh and DSM must then be built on.
  stages.push_back({"georef",
                    [ws] {
                      std::vector<fs::path> in{ws.sparse_dir() / "images.txt"};
                      if (fs::exists(ws.manual_dir() / "gcp_list.txt")) in.push_back(ws.manual_dir() / "gcp_list.txt");
                      return in;
                    },
                    ws.georef_json(), with_telemetry("georef", Needs::kTelemetry, [o, root] {
                      // Unusable telemetry must not cost the user the model: the georeferenced products are
                      // skipped instead (dsm and ortho then say so).
                      try {
                        return geo::RunGeorefStage(root, o.georef);
                      } catch (const Error& e) {
                        spdlog::warn("georef: {} — no georeferenced products", e.what());
                        return nlohmann::json{{"skipped", e.what()}};
                      }
                    })});
  stages.push_back({"dense", [ws] { return std::vector<fs::path>{ws.sparse_dir() / "images.txt"}; },
                    ws.dense_dir() / "fused.ply", [o, root] { return mvs::RunDenseStage(root, o.dense); }});
  stages.push_back({"mesh", [ws] { return std::vector<fs::path>{ws.dense_dir() / "fused.ply"}; },
                    ws.mesh_dir() / "poisson.ply", [o, root] { return surface::RunMeshStage(root, o.mesh); }});
  // report/texture.json is written after the OBJ, GLB and PLY: it marks the stage complete.
  stages.push_back({"texture", [ws] { return std::vector<fs::path>{ws.mesh_dir() / "poisson.ply"}; },
                    ws.report_dir() / "texture.json", [o, root] { return surface::RunTextureStage(root, o.texture); }});
  // 3D Tiles of the dense cloud and the textured mesh, for the console (tiles_stage.h).
  stages.push_back({"tiles",
                    [ws] {
                      return std::vector<fs::path>{ws.dense_dir() / "fused.ply", ws.report_dir() / "texture.json"};
                    },
                    ws.root() / "tiles" / "tileset.json", [root] { return RunTilesStage(root, TilesOptions{}); }});
  stages.push_back({"dsm",
                    [ws] {
                      return std::vector<fs::path>{ws.georef_json(), ws.mesh_dir() / "poisson.ply"};
                    },
                    ws.geo_dir() / "dsm.json",
                    with_telemetry("dsm", Needs::kGeoreference, [o, root] { return geo::RunDsmStage(root, o.dsm); })});
  stages.push_back({"ortho",
                    [ws] {
                      return std::vector<fs::path>{ws.geo_dir() / "dsm.json", ws.report_dir() / "texture.json"};
                    },
                    ws.geo_dir() / "ortho.tif",
                    with_telemetry("ortho", Needs::kGeoreference, [root] { return geo::RunOrthoStage(root); })});
  return stages;
}

nlohmann::json RunReconstruct(const ReconstructOptions& o, std::vector<StageResult>* stage_results) {
  o.Check();
  const core::Workspace ws(o.workspace);
  core::EnsureDirectory(ws.root());
  // One process per workspace; what a killed run was writing is discarded (its stage runs again).
  const core::FileLock lock(ws.lock_file(), ws.root().string());
  if (const size_t n = core::RemoveStaleTemporaries(ws.root()))
    spdlog::info("{}: removed {} unfinished file(s) of an interrupted run", ws.root().string(), n);
  core::EnsureDirectory(ws.report_dir());
  nlohmann::json project;
  project["fmv3d_version"] = FMV3D_VERSION;
  for (const auto& in : o.inputs) project["inputs"].push_back(fs::absolute(in).string());
  project["options"] = {{"camera_file", o.prior.camera_file.string()},
                        {"sensor", o.prior.sensor_name},
                        {"max_frames", o.frames.max_frames},
                        {"sift_max_features", o.sift.max_features},
                        {"fast", o.fast},
                        {"max_memory_mb", o.dense.max_memory_mb},
                        {"from", o.runner.from},
                        {"until", o.runner.until}};
  core::WriteJson(ws.project_json(), project);

  RunnerOptions runner = o.runner;
  runner.state_dir = ws.state_dir();
  const auto results = RunStages(ReconstructStages(o), runner);
  nlohmann::json timings = nlohmann::json::object();
  for (const auto& r : results) timings[r.name] = r.skipped ? nlohmann::json("skipped") : nlohmann::json(r.seconds);
  RecordTimings(ws.root(), timings);
  if (stage_results) *stage_results = results;
  if (!o.report) return {};
  core::AppendProgressEvent({{"event", "stage"}, {"stage", "report"}, {"state", "start"}});
  nlohmann::json report = WriteReport(ws.root());
  core::AppendProgressEvent({{"event", "stage"}, {"stage", "report"}, {"state", "done"}});
  return report;
}

}  // namespace fmv3d::pipeline
