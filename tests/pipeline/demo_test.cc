// The demo's held-out view (pipeline/demo.h): a true frame rendered between two flight frames against a
// model rendered (unshaded) from the same viewpoint. Here the frames are rendered without sun shading, so
// the scene's own mesh (albedo textures) is the perfect model up to the sensor noise, and scores high; the
// same mesh half a metre off scores clearly lower.
#include "fmv3d/pipeline/demo.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "fmv3d/synth/synth.h"
#include "test_util.h"

namespace fmv3d::pipeline {
namespace {

TEST(DemoHeldOut, TrueModelScoresHighAndAShiftedOneLower) {
  test::TempDir dir("fmv3d-demo-heldout");
  synth::SynthOptions s;
  s.scene = synth::SceneKind::kBuilding;
  s.flight.frames = 8;
  s.width = 320;
  s.height = 180;
  s.detail = 0.35;
  s.truth_points = 50;
  s.output = dir / "synth";
  s.render.shading = false;
  synth::RunSynth(s);
  const auto scene = dir / "synth" / "scene.obj";

  const HeldOutResult exact = RenderHeldOut(dir / "synth", scene, core::Sim3(), s.render, dir / "out");
  EXPECT_GT(exact.covered_fraction, 0.5);
  ASSERT_EQ(exact.between.size(), 2u);
  EXPECT_EQ(exact.between[0], "flight-000003.png");
  EXPECT_EQ(exact.between[1], "flight-000004.png");
  for (const char* f : {"truth.png", "model.png", "difference.png"})
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / f)) << f;

  core::Sim3 off;
  off.t = Eigen::Vector3d(0.5, -0.3, 0.2);
  const HeldOutResult shifted = RenderHeldOut(dir / "synth", scene, off, s.render, "");
  std::printf("held-out PSNR: exact model %.2f dB, shifted %.2f dB\n", exact.psnr_db, shifted.psnr_db);
  EXPECT_GT(exact.psnr_db, 35);  // 1.5 DN of noise alone: 44.6 dB; texture filtering costs some
  EXPECT_GT(exact.psnr_db, shifted.psnr_db + 5);
}

}  // namespace
}  // namespace fmv3d::pipeline
