// `fmv3d demo`: the embedded default main job (README's first command). Renders a synthetic flight around the
// CAD building with exact ground truth, reconstructs it from the video alone (no knowledge of the camera),
// measures the result against the truth and the CAD model, and prints the accuracy table.
//
// Layout in `output`: the synthetic flight (flight.mp4, truth/, scene.obj, truth.json), ws/ (the
// reconstruction workspace, report in ws/report/report.html) and demo.json (the accuracy table).
#pragma once

#include <filesystem>

#include <nlohmann/json.hpp>

namespace fmv3d::pipeline {

struct DemoOptions {
  std::filesystem::path output = "demo";
  int frames = 30;
  int width = 960, height = 540;
  int dense_max_size = 480;  // dense working resolution (longer side): keeps the demo to minutes on 2 cores
  uint64_t seed = 1;
  void Check() const;
};

// Returns demo.json's content. Re-running resumes: the flight is rendered once, finished stages are skipped.
nlohmann::json RunDemo(const DemoOptions& options);

}  // namespace fmv3d::pipeline
