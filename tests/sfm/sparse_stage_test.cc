// The sparse stage on a workspace written from synthetic correspondences: files in, COLMAP model + PLY + report
// out, with the reason for an image that cannot be registered.
#include "fmv3d/sfm/sparse_stage.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/sfm/synthetic_correspondences.h"
#include "test_util.h"

namespace fmv3d::sfm {
namespace {

void WriteWorkspace(const SyntheticScene& scene, const std::filesystem::path& ws, bool add_blank) {
  io::FramesIndex index;
  io::CameraPrior prior;
  prior.camera = scene.input.cameras.at(1).camera;
  prior.prior_source =
      fmv3d::io::ParsePriorSource(scene.input.cameras.at(1).focal_known ? "calibration:test" : "guess");
  index.cameras.push_back(prior);
  core::EnsureDirectory(ws / "frames");
  core::EnsureDirectory(ws / "features");
  core::EnsureDirectory(ws / "matches");
  auto images = scene.input.images;
  if (add_blank) {
    MapperImage blank;
    blank.id = static_cast<uint32_t>(images.size() + 1);
    blank.name = "blank.png";
    images.push_back(blank);
  }
  for (const auto& im : images) {
    io::FrameRecord fr;
    fr.name = im.name;
    index.frames.push_back(fr);
    features::FeatureSet fs;
    fs.image_name = im.name;
    fs.width = prior.camera.width;
    fs.height = prior.camera.height;
    for (const auto& k : im.keypoints)
      fs.keypoints.push_back({static_cast<float>(k.x()), static_cast<float>(k.y()), 2, 0});
    fs.descriptors.setZero(static_cast<Eigen::Index>(fs.keypoints.size()), 128);
    fs.colors = im.colors;
    if (fs.colors.size() != fs.keypoints.size()) fs.colors.assign(fs.keypoints.size(), {0, 0, 0});
    features::WriteFeatures(fs, features::FeaturePath(ws / "features", im.name));
  }
  io::WriteFramesIndex(index, ws / "frames" / "frames.json");
  features::WriteMatches(scene.input.pairs, features::MatchesPath(ws / "matches"));
}

TEST(SparseStage, WritesModelPlyAndReport) {
  SyntheticSceneOptions so;
  so.num_cameras = 10;
  so.num_points = 500;
  const auto scene = MakeSyntheticScene(so);
  test::TempDir dir("sparse");
  WriteWorkspace(scene, dir.path(), true);
  const auto report = RunSparseStage(dir.path(), {});
  EXPECT_EQ(report["total_images"], 11);
  EXPECT_EQ(report["registered_images"], 10);
  ASSERT_EQ(report["left_out"].size(), 1u);
  EXPECT_EQ(report["left_out"][0]["image"], "blank.png");
  EXPECT_NE(report["left_out"][0]["reason"].get<std::string>().find("no features"), std::string::npos);
  EXPECT_GT(report["points"].get<int>(), 300);
  EXPECT_LT(report["mean_reprojection_error_px"].get<double>(), 1.0);
  EXPECT_TRUE(report["seconds"].contains("mapping"));
  const auto rec = io::ReadColmapText(dir / "sparse");
  rec.Validate();
  EXPECT_EQ(rec.images.size(), 10u);
  EXPECT_TRUE(std::filesystem::exists(dir / "sparse" / "sparse.ply"));
  EXPECT_GT(std::filesystem::file_size(dir / "sparse" / "sparse.ply"), rec.points.size() * 15);
  const auto json = core::ReadJson(dir / "report" / "sparse.json");
  EXPECT_EQ(json["registered_images"], 10);
  // The scan bounds this short orbit's focal from below only; the first mapping moves it ~27%: mapped again.
  EXPECT_EQ(json["focal_decision"]["decision"], "restart");
  EXPECT_EQ(json["focal_decision"]["restart"]["kept"], "second");
  EXPECT_GT(json["focal_decision"]["restart"]["change"].get<double>(), 0.1);
  // The final model's posterior of each free intrinsic, with the weak flag the operator sees (the focal of
  // 10 images of 0.5 px keypoints: about 4 px, 3 px at the image corner: weak).
  ASSERT_EQ(json["intrinsics_posterior"].size(), 1u);
  const auto& posterior = json["intrinsics_posterior"][0];
  EXPECT_TRUE(posterior["determined"].get<bool>());
  const auto& focal = posterior["parameters"]["f"];
  EXPECT_GT(focal["posterior_sigma"].get<double>(), 0);
  EXPECT_EQ(focal["weakly_determined"].get<bool>(),
            focal["corner_displacement_1sigma_px"].get<double>() > posterior["weak_above_corner_px"].get<double>());
  size_t weak = 0;  // one warning per weakly determined intrinsic (k1 too when the lens was refined)
  for (const auto& [name, p] : posterior["parameters"].items()) weak += p["weakly_determined"].get<bool>() ? 1 : 0;
  EXPECT_GE(weak, focal["weakly_determined"].get<bool>() ? 1u : 0u);
  EXPECT_EQ(posterior["warnings"].size(), weak);
  EXPECT_LE(EvaluateSparse(rec, scene.truth).centre_rmse_fraction, 0.001);
  // The memory section: the bound known before mapping covers the estimate from the model's observations.
  const auto& memory = json["memory"];
  size_t observations = 0;
  for (const auto& [id, p] : rec.points) observations += p.track.size();
  EXPECT_EQ(memory["observations"].get<size_t>(), observations);
  EXPECT_GE(memory["matched_keypoints"].get<size_t>(), observations);
  EXPECT_GE(memory["bound_mb"].get<double>(), memory["estimated_mb"].get<double>());
  EXPECT_GT(memory["estimated_mb"].get<double>(), 0);
  EXPECT_TRUE(memory["within_budget"].get<bool>());

  // The CLI evaluation against the truth written as a COLMAP model.
  io::WriteColmapText(scene.truth, dir / "truth");
  const auto r = test::RunCli("evaluate-sparse " + dir.path().string() + " --truth " + (dir / "truth").string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("median relative rotation error"), std::string::npos);
  const auto ev = core::ReadJson(dir / "report" / "sparse_eval.json");
  EXPECT_LT(ev["centre_rmse_percent_of_extent"].get<double>(), 0.1);

  // A budget below the bound: the stage still runs, and says so before mapping and in the report.
  const auto small = test::RunCli("sparse " + dir.path().string() + " --max-memory 0.01");
  EXPECT_EQ(small.exit_code, 0) << small.err;
  EXPECT_NE(small.err.find("above --max-memory 0.01 MB"), std::string::npos) << small.err;
  EXPECT_FALSE(core::ReadJson(dir / "report" / "sparse.json")["memory"]["within_budget"].get<bool>());

  // A budget nine tenths of the way from the keypoints' own term to the bound: mapped with a share of each image's
  // keypoints, within the budget, every image still registered.
  const double keypoints_mb = 350.0 * memory["keypoints"].get<double>() / 1048576.0;
  const double budget = 0.1 * keypoints_mb + 0.9 * memory["bound_mb"].get<double>();
  const auto thin = test::RunCli("sparse " + dir.path().string() + " --max-memory " + std::to_string(budget));
  EXPECT_EQ(thin.exit_code, 0) << thin.err;
  EXPECT_NE(thin.err.find("of each image's matched keypoints"), std::string::npos) << thin.err;
  const auto thin_json = core::ReadJson(dir / "report" / "sparse.json");
  const auto& thin_memory = thin_json["memory"];
  EXPECT_TRUE(thin_memory["within_budget"].get<bool>());
  EXPECT_LE(thin_memory["bound_mb"].get<double>(), budget);
  EXPECT_LT(thin_memory["thinning"]["keep_fraction"].get<double>(), 1.0);
  EXPECT_LT(thin_memory["correspondences"].get<size_t>(), memory["correspondences"].get<size_t>());
  EXPECT_EQ(thin_json["registered_images"], 10);
}

TEST(SparseStage, MissingInputsAreUserErrors) {
  test::TempDir dir("sparse-missing");
  EXPECT_THROW(RunSparseStage(dir.path(), {}), Error);
  const auto r = test::RunCli("sparse " + dir.path().string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("frames"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace fmv3d::sfm
