// `fmv3d mesh` on a synthetic workspace: an oriented cloud sampled from the true building scene (with noise
// and outliers, as a dense stage delivers) → Poisson mesh, measured against the true surface; and the
// errors a user sees for missing or unusable input.
#include "fmv3d/surface/mesh_stage.h"

#include <gtest/gtest.h>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/surface/synthetic_cloud.h"
#include "synthetic_flight.h"
#include "test_util.h"

namespace fmv3d::surface {
namespace {

namespace fs = std::filesystem;

SyntheticCloudOptions BuildingCloud(double noise) {
  SyntheticCloudOptions o;
  o.spacing = 0.15;
  o.position_noise = noise;
  o.normal_noise_deg = 5;
  o.outlier_share = 0.01;
  o.outlier_range = 2.0;
  o.region = Eigen::AlignedBox3d(Eigen::Vector3d(-18, -18, -3), Eigen::Vector3d(18, 18, 35));
  o.seed = 7;
  return o;
}

TEST(MeshStage, NoisyBuildingCloudMeetsTheAccuracyTargets) {
  const auto& flight = testing::Flight();
  test::TempDir ws("fmv3d-mesh");
  // Noise of 0.1% of the building height (3 cm) per axis, 5° normal noise, 1% outliers.
  const SyntheticCloud cloud =
      PrepareSyntheticWorkspace(flight.synth_dir, ws.path(), BuildingCloud(0.001 * flight.length));
  ASSERT_GT(cloud.cloud.size(), 50000u);
  const nlohmann::json report = RunMeshStage(ws.path(), MeshStageOptions{});
  ASSERT_TRUE(fs::exists(ws / "mesh/poisson.ply"));
  ASSERT_TRUE(fs::exists(ws / "report/mesh.json"));
  EXPECT_EQ(core::ReadJson(ws / "report/mesh.json")["faces"], report["faces"]);
  const ColoredMesh mesh = ReadMeshPly(ws / "mesh/poisson.ply");
  EXPECT_EQ(mesh.triangles.size(), report["faces"].get<size_t>());
  EXPECT_EQ(mesh.colors.size(), mesh.vertices.size());

  const geometry::MeshDistance truth(io::ReadObj(flight.synth_dir / "scene.obj", false));
  const double h = flight.length;
  const MeshAccuracy acc = EvaluateMesh(mesh, truth, cloud.seen_surface, 0.1, 0.01 * h);
  RecordProperty("rms_percent", std::to_string(100 * acc.rms / h));
  RecordProperty("completeness", std::to_string(acc.completeness));
  // RMS ≤ 0.5% of the building height, ≥ 95% of the seen surface within 1%.
  EXPECT_LE(acc.rms, 0.005 * h) << "median " << acc.median << " p90 " << acc.p90;
  EXPECT_GE(acc.completeness, 0.95);
}

TEST(MeshStage, EstimatesMissingNormalsFromTheCameras) {
  const auto& flight = testing::Flight();
  test::TempDir ws("fmv3d-mesh");
  SyntheticCloudOptions o = BuildingCloud(0.0);
  o.spacing = 0.25;
  const SyntheticCloud cloud = PrepareSyntheticWorkspace(flight.synth_dir, ws.path(), o);
  io::OrientedPointCloud no_normals = cloud.cloud;
  no_normals.normals.clear();
  io::WritePointCloudPly(no_normals, ws / "dense/fused.ply");
  const nlohmann::json report = RunMeshStage(ws.path(), MeshStageOptions{});
  EXPECT_EQ(report["normals"], "estimated");
  const ColoredMesh mesh = ReadMeshPly(ws / "mesh/poisson.ply");
  const geometry::MeshDistance truth(io::ReadObj(flight.synth_dir / "scene.obj", false));
  const MeshAccuracy acc = EvaluateMesh(mesh, truth, cloud.seen_surface, 0.2, 0.01 * flight.length);
  EXPECT_LE(acc.rms, 0.01 * flight.length);
  EXPECT_GE(acc.completeness, 0.9);

  // Without visibility the normals cannot be oriented: a clear error, unless estimation is off anyway.
  no_normals.visibility.clear();
  io::WritePointCloudPly(no_normals, ws / "dense/fused.ply");
  try {
    RunMeshStage(ws.path(), MeshStageOptions{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no normals"), std::string::npos) << e.what();
  }
  MeshStageOptions strict;
  strict.estimate_missing_normals = false;
  EXPECT_THROW(RunMeshStage(ws.path(), strict), Error);
}

TEST(MeshStage, MissingOrEmptyCloudIsAClearError) {
  test::TempDir ws("fmv3d-mesh");
  try {
    RunMeshStage(ws.path(), MeshStageOptions{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dense/fused.ply"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("fmv3d dense"), std::string::npos) << e.what();
  }
  core::EnsureDirectory(ws / "dense");
  io::WritePointCloudPly(io::OrientedPointCloud{}, ws / "dense/fused.ply");
  try {
    RunMeshStage(ws.path(), MeshStageOptions{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no points"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(ws / "mesh/poisson.ply"));
}

TEST(MeshStage, CliReportsMissingInputInOneLine) {
  test::TempDir ws("fmv3d-mesh");
  const auto r = test::RunCli("mesh " + ws.path().string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("fmv3d dense"), std::string::npos) << r.err;
  const auto usage = test::RunCli("mesh " + ws.path().string() + " --trim 2");
  EXPECT_NE(usage.exit_code, 0);
}

}  // namespace
}  // namespace fmv3d::surface
