#include "fmv3d/pipeline/reconstruct.h"

#include <spdlog/spdlog.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/pipeline/report.h"
#include "fmv3d/pipeline/workspace.h"

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
}

std::vector<Stage> ReconstructStages(const ReconstructOptions& o) {
  const Workspace ws(o.workspace);
  const fs::path root = ws.root();
  std::vector<Stage> stages;
  stages.push_back({"frames",
                    [o] {
                      // Every input file (folders expanded) is an input of the frames stage.
                      return io::ExpandInputs(o.inputs);
                    },
                    ws.frames_json(),
                    [o, root] {
                      io::IngestOptions io_opt = o.frames;
                      io_opt.workspace = root;
                      const calib::PriorChooser chooser(o.prior, calib::SensorDatabase::LoadDefault());
                      io_opt.prior = chooser.AsFunction();
                      const io::FramesIndex index = io::IngestFrames(o.inputs, io_opt);
                      return nlohmann::json{{"frames", index.frames.size()}, {"cameras", index.cameras.size()}};
                    }});
  stages.push_back({"features", [ws] { return std::vector<fs::path>{ws.frames_json()}; },
                    ws.features_dir() / "features.json",
                    [o, root] {
                      const auto s = features::RunFeaturesStage(root, o.sift);
                      return nlohmann::json{{"images", s.images},
                                            {"keypoints", s.total_keypoints},
                                            {"min_keypoints", s.min_keypoints},
                                            {"max_keypoints", s.max_keypoints}};
                    }});
  stages.push_back({"match", [ws] { return std::vector<fs::path>{ws.features_dir() / "features.json"}; },
                    features::MatchesSummaryPath(ws.matches_dir()),
                    [o, root] {
                      const auto s = features::RunMatchStage(root, o.match);
                      return nlohmann::json{{"pairs_tried", s.pairs_tried}, {"pairs_verified", s.pairs_verified}};
                    }});
  stages.push_back({"sparse",
                    [ws] { return std::vector<fs::path>{features::MatchesSummaryPath(ws.matches_dir())}; },
                    ws.sparse_dir() / "images.txt", [o, root] { return sfm::RunSparseStage(root, o.sparse); }});
  stages.push_back({"dense", [ws] { return std::vector<fs::path>{ws.sparse_dir() / "images.txt"}; },
                    ws.dense_dir() / "fused.ply", [o, root] { return mvs::RunDenseStage(root, o.dense); }});
  stages.push_back({"mesh", [ws] { return std::vector<fs::path>{ws.dense_dir() / "fused.ply"}; },
                    ws.mesh_dir() / "poisson.ply", [o, root] { return surface::RunMeshStage(root, o.mesh); }});
  return stages;
}

nlohmann::json RunReconstruct(const ReconstructOptions& o) {
  o.Check();
  const Workspace ws(o.workspace);
  core::EnsureDirectory(ws.root());
  core::EnsureDirectory(ws.report_dir());
  nlohmann::json project;
  project["fmv3d_version"] = FMV3D_VERSION;
  for (const auto& in : o.inputs) project["inputs"].push_back(fs::absolute(in).string());
  project["options"] = {{"camera_file", o.prior.camera_file.string()},
                        {"sensor", o.prior.sensor_name},
                        {"max_frames", o.frames.max_frames},
                        {"sift_max_features", o.sift.max_features},
                        {"from", o.runner.from},
                        {"until", o.runner.until}};
  core::WriteJson(ws.project_json(), project);

  const auto results = RunStages(ReconstructStages(o), o.runner);
  nlohmann::json timings = nlohmann::json::object();
  for (const auto& r : results) timings[r.name] = r.skipped ? nlohmann::json("skipped") : nlohmann::json(r.seconds);
  nlohmann::json report;
  if (o.report) report = WriteReport(ws.root(), timings);
  return report;
}

}  // namespace fmv3d::pipeline
