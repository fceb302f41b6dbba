// A small synthetic flight around the `building` scene shared by the surface tests: rendered once for all the
// test processes of the binary (frames, truth, scene.obj; test::SharedFixture).
#pragma once

#include <filesystem>
#include <memory>

#include "fmv3d/core/files.h"
#include "fmv3d/synth/synth.h"
#include "test_util.h"

namespace fmv3d::surface::testing {

struct SyntheticFlight {
  std::filesystem::path synth_dir;
  double length = 0;  // characteristic length (building height)
};

// 13 frames of 480x270 on an orbit; frame 6 is meant to be held out of the workspace.
inline const SyntheticFlight& Flight() {
  static const SyntheticFlight flight = [] {
    SyntheticFlight f;
    f.synth_dir = test::SharedFixture("surface-building-flight",
                                      [](const std::filesystem::path& dir) {
                                        synth::SynthOptions o;
                                        o.scene = synth::SceneKind::kBuilding;
                                        o.flight.frames = 13;
                                        o.flight.seed = 5;
                                        o.width = 480;
                                        o.height = 270;
                                        o.detail = 0.35;
                                        o.truth_points = 100;
                                        o.output = dir / "synth";
                                        synth::RunSynth(o);
                                      }) /
                  "synth";
    f.length = core::ReadJson(f.synth_dir / "truth.json").at("characteristic_length").get<double>();
    return f;
  }();
  return flight;
}

inline const char* kHeldOut = "flight-000006.png";

}  // namespace fmv3d::surface::testing
