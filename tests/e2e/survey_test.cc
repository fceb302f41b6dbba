// End to end on a low-texture nadir survey, as a user runs it: `fmv3d synth` renders a lawn-mower grid at
// 70% forward / 40% side overlap over the `sand` scene (faint sand ripples, dry grass, ponds: a few digital
// numbers of contrast), then frames → features → match → sparse with default options, the focal given as a
// survey camera's EXIF states it (synth's JPEGs carry none; a nadir grid over near-flat ground leaves a guessed
// focal ambiguous with the flying height). With a fixed SIFT contrast threshold such frames give tens of
// keypoints and most of them stay unregistered; every frame must register, cameras within 0.2% of the extent
// (measured 0.073%).
#include <gtest/gtest.h>

#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::test {
namespace {

void Cli(const std::string& args) {
  const auto r = RunCli(args);
  ASSERT_EQ(r.exit_code, 0) << "fmv3d " << args << "\n" << r.err;
}

TEST(E2eSurvey, LowTextureNadirGridRegistersEveryImage) {
  TempDir dir("fmv3d-e2e-survey");
  const std::string synth = (dir / "synth").string(), ws = (dir / "ws").string();
  Cli("-q synth --scene sand --path grid --overlap 70,40 --frames 16 --size 800x450 --altitude 90 --detail 0.5 "
      "--format jpg --no-scene --seed 5 -o " +
      synth);
  Cli("-q frames " + synth + "/frames -o " + ws);
  Cli("-q features " + ws);
  Cli("-q match " + ws);
  Cli("-q sparse " + ws + " --focal 692.8203");  // 800 px at 60 degrees horizontal field of view
  Cli("-q evaluate-sparse " + ws + " --truth " + synth + "/truth");
  const auto feats = core::ReadJson(dir / "ws/features/features.json");
  const auto sparse = core::ReadJson(dir / "ws/report/sparse.json");
  const auto eval = core::ReadJson(dir / "ws/report/sparse_eval.json");
  std::cout << "keypoints " << feats.at("mean_keypoints") << ", adapted " << feats.at("adapted_contrast_images") << "\n"
            << sparse.at("left_out").dump() << "\n"
            << eval.dump(2) << "\n";
  EXPECT_GT(feats.at("adapted_contrast_images").get<int>(), 0) << "the scene is meant to be weak";
  EXPECT_EQ(sparse.at("registered_images").get<int>(), 16) << "every image registered";
  EXPECT_EQ(eval.at("matched_images").get<int>(), 16);
  EXPECT_LE(eval.at("mean_reprojection_error_px").get<double>(), 1.0);
  EXPECT_LE(eval.at("centre_rmse_percent_of_extent").get<double>(), 0.2);
}

}  // namespace
}  // namespace fmv3d::test
