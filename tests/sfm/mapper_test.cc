// End-to-end incremental mapper on synthetic correspondences with exact ground truth.
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <random>

#include "fmv3d/core/error.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/sfm/incremental_mapper.h"
#include "fmv3d/sfm/synthetic_correspondences.h"

namespace fmv3d::sfm {
namespace {

struct Outcome {
  MapperResult result;
  SparseEvaluation eval;
};

Outcome RunAndEvaluate(const SyntheticScene& scene, const MapperOptions& options = {}) {
  Outcome out;
  out.result = RunIncrementalMapper(scene.input, options);
  if (!out.result.models.empty()) out.eval = EvaluateSparse(out.result.models[0], scene.truth);
  const auto& rec = out.result.models.empty() ? core::Reconstruction() : out.result.models[0];
  std::printf("%s\n", out.result.stats.dump().c_str());
  if (!rec.cameras.empty()) {
    const auto& c = rec.cameras.begin()->second;
    std::printf("registered %zu/%zu, points %zu, track %.2f, reproj %.3f px, centre %.4f%%, rot %.4f deg, "
                "focal %.4f%% (f %.2f k1 %.4f k2 %.4f pp %.1f %.1f)\n",
                rec.images.size(), scene.input.images.size(), rec.points.size(), rec.MeanTrackLength(),
                rec.MeanReprojectionError(), 100 * out.eval.centre_rmse_fraction,
                out.eval.median_rotation_error_deg, 100 * out.eval.focal_relative_error, c.f, c.k1, c.k2, c.u0,
                c.v0);
  }
  return out;
}

TEST(IncrementalMapper, OrbitSelfCalibratesFocalAndDistortion) {
  SyntheticSceneOptions so;  // 40 cameras, 2000 points, 0.5 px noise, 10% outliers, f guessed, k1 = -0.08
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  const auto& rec = out.result.models[0];
  EXPECT_EQ(rec.images.size(), scene.input.images.size());
  EXPECT_LE(out.eval.centre_rmse_fraction, 0.0002);
  EXPECT_LE(out.eval.median_rotation_error_deg, 0.03);
  EXPECT_LE(out.eval.focal_relative_error, 0.001);
  EXPECT_NEAR(rec.cameras.begin()->second.k1, so.k1, 0.01);  // k2 (truth 0) is free and trades with k1
  EXPECT_LE(rec.MeanReprojectionError(), 0.9);  // ≈ the 0.5 px noise (mean of |2D noise| is 0.63 px)
  EXPECT_TRUE(out.result.left_out.empty());
  rec.Validate();
}

TEST(IncrementalMapper, NadirGridOverNearPlanarTerrain) {
  SyntheticSceneOptions so;
  so.layout = SyntheticSceneOptions::Layout::kNadirGrid;
  so.num_cameras = 32;
  so.num_points = 1500;
  const auto scene = MakeSyntheticScene(so);
  const auto out = RunAndEvaluate(scene);
  ASSERT_FALSE(out.result.models.empty());
  EXPECT_EQ(out.result.models[0].images.size(), scene.input.images.size());
  EXPECT_LE(out.eval.centre_rmse_fraction, 0.001);
  EXPECT_LE(out.result.models[0].MeanReprojectionError(), 0.9);
}

// Bad input: unrelated images, a frame without features, a frame with too few matches, matches with indices
// out of range. The scene still reconstructs; each bad frame is left out with a reason; nothing throws.
TEST(IncrementalMapper, BadInputIsLeftOutWithAReason) {
  SyntheticSceneOptions so;
  so.num_cameras = 12;
  so.num_points = 600;
  so.guess_focal_factor = 0;  // known focal: this test is about bad frames
  auto scene = MakeSyntheticScene(so);
  auto& in = scene.input;
  std::mt19937_64 rng(3);
  // Two unrelated images, matched to each other with random (geometrically meaningless) matches.
  for (uint32_t id : {100u, 101u}) {
    MapperImage im;
    im.id = id;
    im.name = "unrelated-" + std::to_string(id) + ".png";
    for (int k = 0; k < 500; ++k) im.keypoints.emplace_back(rng() % 1280 + 0.5, rng() % 720 + 0.5);
    in.images.push_back(im);
  }
  features::VerifiedPair junk;
  junk.image_id1 = 100;
  junk.image_id2 = 101;
  for (uint32_t k = 0; k < 200; ++k) junk.inliers.push_back({k, static_cast<uint32_t>(rng() % 500)});
  in.pairs.push_back(junk);
  // A blank frame (no features) and one with a handful of matches to image 1.
  MapperImage blank;
  blank.id = 102;
  blank.name = "blank.png";
  in.images.push_back(blank);
  MapperImage weak;
  weak.id = 103;
  weak.name = "weak.png";
  for (int k = 0; k < 10; ++k) weak.keypoints.emplace_back(100 + 10 * k, 200);
  in.images.push_back(weak);
  features::VerifiedPair few;
  few.image_id1 = 1;
  few.image_id2 = 103;
  for (uint32_t k = 0; k < 8; ++k) few.inliers.push_back({k, k});
  in.pairs.push_back(few);
  // Out-of-range indices and an unknown image id.
  features::VerifiedPair broken;
  broken.image_id1 = 2;
  broken.image_id2 = 3;
  broken.inliers.push_back({1000000, 5});
  in.pairs.push_back(broken);
  broken.image_id2 = 999;
  in.pairs.push_back(broken);

  MapperResult result;
  ASSERT_NO_THROW(result = RunIncrementalMapper(in, {}));
  ASSERT_FALSE(result.models.empty());
  EXPECT_EQ(result.models[0].images.size(), 12u);
  for (uint32_t id : {100u, 101u, 102u, 103u}) {
    ASSERT_TRUE(result.left_out.count(id)) << id;
    EXPECT_FALSE(result.left_out.at(id).empty());
  }
  EXPECT_NE(result.left_out.at(102).find("no features"), std::string::npos) << result.left_out.at(102);
  EXPECT_NE(result.left_out.at(103).find("too few"), std::string::npos) << result.left_out.at(103);
  EXPECT_EQ(result.left_out.size(), 4u);
  const auto ev = EvaluateSparse(result.models[0], scene.truth);
  EXPECT_LE(ev.centre_rmse_fraction, 0.001);
}

TEST(IncrementalMapper, NothingToReconstruct) {
  MapperInput in;
  in.cameras[1].camera = core::Camera::Pinhole(640, 480, 600);
  MapperResult r;
  ASSERT_NO_THROW(r = RunIncrementalMapper(in, {}));
  EXPECT_TRUE(r.models.empty());
  MapperImage a;
  a.id = 1;
  a.name = "a.png";
  a.camera_id = 7;  // unknown camera: inconsistent input is a user error
  in.images.push_back(a);
  EXPECT_THROW(RunIncrementalMapper(in, {}), Error);
}

}  // namespace
}  // namespace fmv3d::sfm
