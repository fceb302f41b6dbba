// `fmv3d demo`: the embedded default main job (README's first command). Renders a synthetic flight around the
// CAD building with exact ground truth, reconstructs it from the video alone (no knowledge of the camera),
// measures the result against the truth and the CAD model, and prints the accuracy table.
//
// Layout in `output`: the synthetic flight (flight.mp4, truth/, scene.obj, truth.json), ws/ (the
// reconstruction workspace, report in ws/report/report.html), heldout/ (a true frame from a viewpoint between
// two flight frames, which the reconstruction never saw, and the textured model rendered from it) and
// demo.json (the accuracy table, with each stage's wall and CPU seconds).
//
// The demo's own run uses cheaper options than `fmv3d reconstruct`'s defaults, sound for a 30-frame video
// orbit: a lighter PatchMatch (fewer sources and rounds, no geometric-consistency pass: fusion's multi-view
// checks and occluding-edge filter remove the outliers). Features stay at 8000 per frame and pairs exhaustive:
// with the VNNI matcher that costs ~20 CPU-s more than 4000 features, and 4000 made the cameras ~5x less
// accurate (focal 0.87% vs 0.10%). bench/RESULTS.md has the figures.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/pose.h"
#include "fmv3d/render/renderer.h"

namespace fmv3d::pipeline {

struct DemoOptions {
  std::filesystem::path output = "demo";
  int frames = 30;
  int width = 960, height = 540;
  int dense_max_size = 480;       // dense working resolution (longer side): keeps the demo to minutes on 2 cores
  int max_features = 8000;        // SIFT features per frame
  bool sequential_pairs = false;  // each frame with the next pair_overlap (+ loop closure) instead of all
  int pair_overlap = 4;
  int dense_sources = 4;         // PatchMatch source views per reference
  int dense_iterations = 3;      // PatchMatch photometric rounds
  bool dense_geometric = false;  // PatchMatch's geometric pass: on the demo it cost 1/3 of dense for no accuracy
  uint64_t seed = 1;
  void Check() const;
};

// The held-out view: the viewpoint halfway between the two middle frames of `synth_dir`'s
// flight (not a frame of the video), the true frame rendered there from scene.obj as `fmv3d synth` renders
// frames, and the textured model (OBJ, mapped into the world by model_to_world) rendered unshaded from it.
struct HeldOutResult {
  double psnr_db = 0;                // over the pixels the model covers, 8-bit RGB
  double covered_fraction = 0;       // of the frame's pixels
  std::vector<std::string> between;  // the two flight frames it lies between
};
// `frame_options`: how synth rendered the flight's frames (sun, noise; its noise seed is replaced). Writes
// truth.png, model.png and difference.png (|difference| x 4) to output_dir unless it is empty.
HeldOutResult RenderHeldOut(const std::filesystem::path& synth_dir, const std::filesystem::path& textured_obj,
                            const core::Sim3& model_to_world, const render::RenderOptions& frame_options,
                            const std::filesystem::path& output_dir);

// Returns demo.json's content. Re-running resumes: the flight is rendered once, finished stages are skipped.
nlohmann::json RunDemo(const DemoOptions& options);

}  // namespace fmv3d::pipeline
