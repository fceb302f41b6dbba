#include "fmv3d/surface/mesh_stage.h"

#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <map>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/surface/free_space.h"

namespace fmv3d::surface {

namespace fs = std::filesystem;

void MeshStageOptions::Check() const {
  poisson.Check();
  if (normal_neighbours < 3) throw Error("mesh: normal estimation needs at least 3 neighbours");
}

void EstimateNormalsTowardsCameras(io::OrientedPointCloud* cloud, const fs::path& sparse_dir, int k) {
  if (!cloud->has_visibility())
    throw Error("the point cloud has no normals and no visibility lists to orient estimated ones");
  if (!fs::exists(sparse_dir / "images.txt"))
    throw Error("the point cloud has no normals; orienting estimated ones needs the cameras in " + sparse_dir.string() +
                " — run `fmv3d sparse` first");
  const core::Reconstruction rec = io::ReadColmapText(sparse_dir);
  std::map<uint32_t, Eigen::Vector3d> centres;
  for (const auto& [id, im] : rec.images) centres[id] = im.pose.Centre();
  open3d::geometry::PointCloud pc;
  pc.points_ = cloud->positions;
  pc.EstimateNormals(open3d::geometry::KDTreeSearchParamKNN(k), true);
  cloud->normals.resize(cloud->size());
  for (size_t i = 0; i < cloud->size(); ++i) {
    Eigen::Vector3d towards = Eigen::Vector3d::Zero();
    for (uint32_t id : cloud->visibility[i]) {
      auto it = centres.find(id);
      if (it == centres.end())
        throw Error("point cloud visibility names image " + std::to_string(id) + ", which " + sparse_dir.string() +
                    " does not have");
      towards += (it->second - cloud->positions[i]).normalized();
    }
    Eigen::Vector3d n = pc.normals_[i];
    if (n.dot(towards) < 0) n = -n;
    cloud->normals[i] = n.cast<float>();
  }
}

nlohmann::json RunMeshStage(const core::Workspace& workspace, const MeshStageOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  const std::string ws = workspace.name();
  const fs::path fused = workspace.dense_dir() / "fused.ply";
  if (!fs::exists(workspace.root())) throw Error(ws + ": no such workspace folder");
  if (!fs::exists(fused)) throw Error(ws + ": no dense/fused.ply — run `fmv3d dense " + ws + "` first");
  io::OrientedPointCloud cloud = io::ReadPointCloudPly(fused);
  if (cloud.empty())
    throw Error(fused.string() +
                ": the dense cloud has no points (check report/dense.json; the dense stage found "
                "no consistent depths)");
  nlohmann::json report;
  report["input"] = fs::relative(fused, workspace.root()).string();
  report["normals"] = "input";
  if (!cloud.has_normals()) {
    if (!options.estimate_missing_normals)
      throw Error(fused.string() + ": the cloud has no normals (nx ny nz), which Poisson reconstruction needs");
    spdlog::warn("{}: no normals in the cloud; estimating them from {} neighbours, oriented towards the cameras",
                 fused.string(), options.normal_neighbours);
    try {
      EstimateNormalsTowardsCameras(&cloud, workspace.sparse_dir(), options.normal_neighbours);
    } catch (const Error& e) {
      throw Error(fused.string() + ": " + e.what());
    }
    report["normals"] = "estimated";
  }
  nlohmann::json stats;
  ColoredMesh mesh = ReconstructPoisson(cloud, options.poisson, &stats);
  // Pieces the cameras see through (free_space.h): needs the points' visibility and the cameras.
  if (cloud.has_visibility() && fs::exists(workspace.sparse_dir() / "images.txt")) {
    const core::Reconstruction rec = io::ReadColmapText(workspace.sparse_dir());
    std::map<uint32_t, FreeSpaceView> views;
    for (const auto& [id, im] : rec.images) views[id] = {rec.cameras.at(im.camera_id), im.pose};
    const FreeSpaceStats fs_stats = DropPiecesInFreeSpace(&mesh, cloud, views);
    report["free_space"] = {{"pieces", fs_stats.pieces},
                            {"tested", fs_stats.tested},
                            {"dropped", fs_stats.dropped},
                            {"faces_dropped", fs_stats.faces_dropped}};
    spdlog::info("mesh: {} of {} pieces seen through by the cameras dropped ({} faces)", fs_stats.dropped,
                 fs_stats.pieces, fs_stats.faces_dropped);
    if (mesh.empty()) throw Error(ws + ": every mesh piece was seen through by the cameras");
  }
  const fs::path mesh_dir = workspace.mesh_dir(), report_dir = workspace.report_dir();
  core::EnsureDirectory(mesh_dir);
  core::EnsureDirectory(report_dir);
  WriteMeshPly(mesh, mesh_dir / "poisson.ply");
  report["output"] = "mesh/poisson.ply";
  report["poisson"] = stats;
  report["vertices"] = mesh.vertices.size();
  report["faces"] = mesh.triangles.size();
  report["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  core::WriteJson(report_dir / "mesh.json", report);
  spdlog::info("mesh: {} vertices, {} faces → {}", mesh.vertices.size(), mesh.triangles.size(),
               (mesh_dir / "poisson.ply").string());
  return report;
}

}  // namespace fmv3d::surface
