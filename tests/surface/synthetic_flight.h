// A small synthetic flight around the `building` scene shared by the surface tests: rendered once per test
// binary (frames, truth, scene.obj) into a temporary folder.
#pragma once

#include <filesystem>
#include <memory>

#include "fmv3d/synth/synth.h"
#include "test_util.h"

namespace fmv3d::surface::testing {

struct SyntheticFlight {
  test::TempDir dir{"fmv3d-surface"};
  std::filesystem::path synth_dir;
  double length = 0;  // characteristic length (building height)
};

// 13 frames of 480x270 on an orbit; frame 6 is meant to be held out of the workspace.
inline const SyntheticFlight& Flight() {
  static std::unique_ptr<SyntheticFlight> flight = [] {
    auto f = std::make_unique<SyntheticFlight>();
    synth::SynthOptions o;
    o.scene = synth::SceneKind::kBuilding;
    o.flight.frames = 13;
    o.flight.seed = 5;
    o.width = 480;
    o.height = 270;
    o.detail = 0.35;
    o.truth_points = 100;
    o.output = f->dir / "synth";
    f->length = synth::RunSynth(o).characteristic_length;
    f->synth_dir = o.output;
    return f;
  }();
  return *flight;
}

inline const char* kHeldOut = "flight-000006.png";

}  // namespace fmv3d::surface::testing
