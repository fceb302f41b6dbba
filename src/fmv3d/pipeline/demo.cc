#include "fmv3d/pipeline/demo.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>

#include "fmv3d/align/compare.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/pipeline/reconstruct.h"
#include "fmv3d/pipeline/report.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/synth/synth.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

void DemoOptions::Check() const {
  if (output.empty()) throw Error("demo: no output folder");
  if (frames < 8) throw Error("demo: at least 8 frames are needed");
  if (width < 160 || height < 120) throw Error("demo: frame size too small (at least 160x120)");
}

nlohmann::json RunDemo(const DemoOptions& o) {
  o.Check();
  core::EnsureDirectory(o.output);
  const fs::path video = o.output / "flight.mp4";
  const fs::path truth_json = o.output / "truth.json";
  if (!fs::exists(video) || !fs::exists(truth_json)) {
    spdlog::info("demo: rendering a {}-frame {}x{} orbit around the CAD building", o.frames, o.width, o.height);
    synth::SynthOptions s;
    s.scene = "building";
    s.flight.path = "orbit";
    s.flight.frames = o.frames;
    s.flight.seed = o.seed;
    s.width = o.width;
    s.height = o.height;
    s.format = "mp4";
    // One frame every half second, all kept: a 20 s orbit sampled as a keyframe selector would.
    s.fps = 2;
    s.output = o.output;
    synth::RunSynth(s);
  }
  const double height = core::ReadJson(truth_json).at("characteristic_length").get<double>();

  ReconstructOptions r;
  r.inputs = {video};
  r.workspace = o.output / "ws";
  r.frames.keyframes.all_frames = true;  // the flight is already sparse in time (see fps above)
  r.report = false;                      // written below, once the comparison is there to link
  r.dense.max_size = o.dense_max_size;
  RunReconstruct(r);

  // Accuracy: cameras against the exact truth (similarity by frame name), surfaces against the CAD model.
  const core::Reconstruction truth = io::ReadColmapText(o.output / "truth");
  const core::Reconstruction model = io::ReadColmapText(r.workspace / "sparse");
  const sfm::SparseEvaluation ev = sfm::EvaluateSparse(model, truth);
  nlohmann::json demo;
  demo["building_height_m"] = height;
  demo["frames"] = o.frames;
  demo["registered"] = model.images.size();
  demo["sparse"] = ev.ToJson();
  demo["sparse"]["mean_reprojection_error_px"] = model.MeanReprojectionError();
  // The Poisson mesh against the CAD model, brought into its frame by the camera alignment (+ scaled ICP).
  // The CAD model is the building itself (scene.obj's building_* materials), not the terrain around it.
  const io::TexturedMesh scene = io::ReadObj(o.output / "scene.obj", /*load_textures=*/false);
  // Only its own vertices are kept, so the CAD's bounds (compare's crop box) are the building's.
  io::TexturedMesh cad;
  std::vector<int> remap(scene.vertices.size(), -1);
  for (const auto& f : scene.faces)
    if (f.material >= 0 && scene.materials[f.material].name.rfind("building", 0) == 0) {
      io::Face g;
      for (int k = 0; k < 3; ++k) {
        int& id = remap[f.v[k]];
        if (id < 0) {
          id = static_cast<int>(cad.vertices.size());
          cad.vertices.push_back(scene.vertices[f.v[k]]);
        }
        g.v[k] = id;
      }
      cad.faces.push_back(g);
    }
  if (cad.faces.empty()) throw Error((o.output / "scene.obj").string() + ": no building faces");
  io::WriteObj(cad, o.output / "cad.obj");
  align::CompareOptions c;
  c.reconstruction = r.workspace / "mesh" / "poisson.ply";
  c.cad = o.output / "cad.obj";
  c.length = height;
  c.transform = ev.alignment;
  c.cameras = o.output / "truth";
  c.output_dir = r.workspace / "report" / "compare";
  const align::CompareResult cmp = align::CompareToCad(c);
  demo["mesh_vs_cad"] = cmp.ToJson();
  core::WriteJson(o.output / "demo.json", demo);
  WriteReport(r.workspace);

  std::printf("\nfmv3d demo: %d-frame synthetic orbit (%dx%d) around a %.0f m building\n", o.frames, o.width,
              o.height, height);
  std::printf("  %-44s %zu / %d\n", "registered frames", model.images.size(), o.frames);
  std::printf("  %-44s %.4f %%\n", "camera centre RMSE (of the orbit's extent)", 100 * ev.centre_rmse_fraction);
  std::printf("  %-44s %.4f deg\n", "median relative rotation error", ev.median_rotation_error_deg);
  std::printf("  %-44s %.4f %%\n", "focal length error", 100 * ev.focal_relative_error);
  std::printf("  %-44s %.3f px\n", "mean reprojection error", model.MeanReprojectionError());
  std::printf("  Poisson mesh vs CAD (%% of the building height, %zu vertices measured):\n", cmp.points_measured);
  std::printf("    %-10s %8s %8s %8s %8s %8s\n", "axis", "mean", "sigma", "RMS", "p50", "p90");
  const std::pair<const char*, const align::ErrorStats*> rows[] = {
      {"X", &cmp.x}, {"Y", &cmp.y}, {"Z", &cmp.z}, {"distance", &cmp.total}};
  for (const auto& [name, e] : rows)
    std::printf("    %-10s %8.3f %8.3f %8.3f %8.3f %8.3f\n", name, 100 * e->mean, 100 * e->std, 100 * e->rms,
                100 * e->p50, 100 * e->p90);
  std::printf("  %-44s %.1f %%\n", "completeness (seen surface within 1% of height)", 100 * cmp.completeness);
  std::printf("\n  report:  %s\n  compare: %s\n  model:   %s\n  table:   %s\n",
              (r.workspace / "report" / "report.html").c_str(), (c.output_dir / "compare.html").c_str(),
              (r.workspace / "mesh" / "model.glb").c_str(), (o.output / "demo.json").c_str());
  return demo;
}

}  // namespace fmv3d::pipeline
