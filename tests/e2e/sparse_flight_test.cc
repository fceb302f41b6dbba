// End to end, as a user runs it: `fmv3d synth` renders an orbit with exact cameras and an unknown lens
// (focal starts from the 1.2·max(w,h) guess, k1 = −0.08), then frames → features → match → sparse, and
// evaluate-sparse compares the result with the truth. The bench's figures are for 80 frames at 1280x720 (measured
// in bench/RESULTS.md: 0.0035%, 0.0148°, 0.016%). To fit CI this flight is 24 frames at 960x540: `match` pairs
// every frame with every other up to 50 images (276 pairs here), and matching is most of the test's cost (36
// frames, 630 pairs: ≈ 526 CPU-s for the test; 24 frames: ≈ 258). The rotation bound is 0.05° (fewer, smaller
// frames than the bench's); the other bounds are the issue's. Measured with 24 frames: centre 0.0034% of the
// extent, rotation 0.0044°, focal 0.0022%, 0.24 px (36 frames: 0.0037%, 0.0051°, 0.0085%, 0.25 px).
#include <gtest/gtest.h>

#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::test {
namespace {

void Cli(const std::string& args) {
  const auto r = RunCli(args);
  ASSERT_EQ(r.exit_code, 0) << "fmv3d " << args << "\n" << r.err;
}

TEST(E2eSparse, SyntheticOrbitUnknownLens) {
  TempDir dir("fmv3d-e2e-sparse");
  const std::string synth = (dir / "synth").string(), ws = (dir / "ws").string();
  Cli("-q synth --scene town --path orbit --frames 24 --size 960x540 --distortion -0.08,0,0,0 --seed 7 -o " + synth);
  Cli("-q frames " + synth + "/frames -o " + ws);
  Cli("-q features " + ws);
  Cli("-q match " + ws);
  Cli("-q sparse " + ws);
  Cli("-q evaluate-sparse " + ws + " --truth " + synth + "/truth");
  const auto eval = core::ReadJson(dir / "ws/report/sparse_eval.json");
  std::cout << eval.dump(2) << "\n";
  EXPECT_EQ(eval.at("matched_images").get<int>(), 24) << "every frame registered";
  EXPECT_LE(eval.at("centre_rmse_percent_of_extent").get<double>(), 0.02);
  EXPECT_LE(eval.at("median_relative_rotation_error_deg").get<double>(), 0.05);
  EXPECT_LE(std::abs(eval.at("focal_relative_error_percent").get<double>()), 0.1);
  EXPECT_LE(eval.at("mean_reprojection_error_px").get<double>(), 0.5);
}

}  // namespace
}  // namespace fmv3d::test
