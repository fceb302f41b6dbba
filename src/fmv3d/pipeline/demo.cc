#include "fmv3d/pipeline/demo.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "fmv3d/align/compare.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/pipeline/reconstruct.h"
#include "fmv3d/pipeline/report.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/sfm/evaluation.h"
#include "fmv3d/synth/synth.h"

namespace fmv3d::pipeline {

namespace fs = std::filesystem;

void DemoOptions::Check() const {
  if (output.empty()) throw Error("demo: no output folder");
  if (frames < 8) throw Error("demo: at least 8 frames are needed");
  if (width < 160 || height < 120) throw Error("demo: frame size too small (at least 160x120)");
  if (max_features < 500) throw Error("demo: at least 500 features per frame are needed");
  if (pair_overlap < 2) throw Error("demo: the pair overlap must be at least 2");
}

HeldOutResult RenderHeldOut(const fs::path& synth_dir, const fs::path& textured_obj, const core::Sim3& model_to_world,
                            const render::RenderOptions& frame_render, const fs::path& output_dir) {
  const core::Reconstruction truth = io::ReadColmapText(synth_dir / "truth");
  if (truth.images.size() < 2) throw Error((synth_dir / "truth").string() + ": fewer than two frames");
  // The viewpoint halfway between the two middle frames of the flight (rotation slerp, centre midpoint).
  std::vector<const core::Image*> images;
  for (const auto& [id, im] : truth.images) images.push_back(&im);
  std::sort(images.begin(), images.end(), [](auto* a, auto* b) { return a->name < b->name; });
  const core::Image& a = *images[images.size() / 2 - 1];
  const core::Image& b = *images[images.size() / 2];
  const Eigen::Quaterniond q = a.pose.q.slerp(0.5, b.pose.q);
  const core::Pose pose =
      core::Pose::FromRotationAndCentre(q.toRotationMatrix(), 0.5 * (a.pose.Centre() + b.pose.Centre()));
  const core::Camera& camera = truth.cameras.at(a.camera_id);

  // The true frame: the scene rendered as `fmv3d synth` renders its frames (sun, noise).
  const io::TexturedMesh scene = io::ReadObj(synth_dir / "scene.obj", /*load_textures=*/true);
  render::RenderOptions frame_options = frame_render;
  frame_options.noise_seed = 0x5eed;
  const cv::Mat frame = render::Renderer(scene).Render(camera, pose, frame_options).image;

  // The textured model, brought into the world (truth) frame, rendered unshaded (its texture has the light).
  io::TexturedMesh model = io::ReadObj(textured_obj, /*load_textures=*/true);
  for (auto& v : model.vertices) v = model_to_world.Apply(v);
  for (auto& n : model.normals) n = (model_to_world.q.cast<float>() * n).normalized();
  render::RenderOptions model_options;
  model_options.shading = false;
  const render::RenderResult r = render::Renderer(model).Render(camera, pose, model_options);

  HeldOutResult res;
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x) {
      if (r.face.at<int32_t>(y, x) < 0) continue;
      const cv::Vec3b &p = r.image.at<cv::Vec3b>(y, x), &t = frame.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) se += double(p[c] - t[c]) * (p[c] - t[c]);
      ++n;
    }
  res.covered_fraction = double(n) / (double(frame.rows) * frame.cols);
  res.psnr_db = n ? 10 * std::log10(255.0 * 255.0 / (se / (3.0 * n))) : 0;
  res.between = {a.name, b.name};
  if (!output_dir.empty()) {
    core::EnsureDirectory(output_dir);
    cv::Mat diff;
    cv::absdiff(frame, r.image, diff);
    const cv::Mat uncovered = r.face < 0;
    diff.setTo(cv::Scalar::all(0), uncovered);
    cv::imwrite((output_dir / "truth.png").string(), frame);
    cv::imwrite((output_dir / "model.png").string(), r.image);
    cv::imwrite((output_dir / "difference.png").string(), cv::Mat(diff * 4));
  }
  return res;
}

namespace {

// The embedded flight: an orbit video around the CAD building with exact ground truth (rendered once).
void RenderDemoFlight(const DemoOptions& o) {
  spdlog::info("demo: rendering a {}-frame {}x{} orbit around the CAD building", o.frames, o.width, o.height);
  synth::SynthOptions s;
  s.scene = synth::SceneKind::kBuilding;
  s.flight.path = synth::FlightPath::kOrbit;
  s.flight.frames = o.frames;
  s.flight.seed = o.seed;
  s.width = o.width;
  s.height = o.height;
  s.format = synth::OutputFormat::kMp4;
  // One frame every half second, all kept: a 20 s orbit sampled as a keyframe selector would.
  s.fps = 2;
  s.output = o.output;
  synth::RunSynth(s);
}

ReconstructOptions DemoReconstructOptions(const DemoOptions& o, const fs::path& video) {
  ReconstructOptions r;
  r.inputs = {video};
  r.workspace = o.output / "ws";
  r.frames.keyframes.all_frames = true;  // the flight is already sparse in time (see fps above)
  r.report = false;                      // written below, once the comparison is there to link
  r.dense.max_size = o.dense_max_size;
  r.dense.max_sources = o.dense_sources;
  r.dense.patch_match.iterations = o.dense_iterations;
  r.dense.geometric = o.dense_geometric;
  r.sift.max_features = o.max_features;
  if (o.sequential_pairs) {
    r.match.pairs.mode = features::PairMode::kSequential;
    r.match.pairs.overlap = o.pair_overlap;
    r.match.pairs.quadratic = false;  // an orbit's frames 2^k apart see other sides; loop closure finds the rest
  } else {
    r.match.pairs.mode = features::PairMode::kExhaustive;
  }
  return r;
}

// The CAD model is the building itself (scene.obj's building_* materials), not the terrain around it; only its
// own vertices are kept, so the CAD's bounds (compare's crop box) are the building's.
io::TexturedMesh BuildingOnly(const io::TexturedMesh& scene) {
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
  return cad;
}

struct Seconds {
  double wall = 0, cpu = 0;
};

// Each stage's wall and CPU seconds, the evaluation's and the total (skipped stages not counted).
nlohmann::json StageTiming(const std::vector<StageResult>& stages, Seconds eval) {
  nlohmann::json timing = nlohmann::json::object();
  Seconds total;
  for (const auto& st : stages) {
    if (st.skipped) {
      timing[st.name] = "skipped";
      continue;
    }
    timing[st.name] = {{"wall_s", st.seconds}, {"cpu_s", st.cpu_seconds}};
    total.wall += st.seconds;
    total.cpu += st.cpu_seconds;
  }
  timing["evaluation"] = {{"wall_s", eval.wall}, {"cpu_s", eval.cpu}};
  timing["total"] = {{"wall_s", total.wall + eval.wall}, {"cpu_s", total.cpu + eval.cpu}};
  return timing;
}

// What a user reads at the end of `fmv3d demo`.
struct DemoSummary {
  double height = 0;
  size_t registered = 0;
  double reprojection_px = 0;
  sfm::SparseEvaluation sparse;
  align::CompareResult mesh;
  HeldOutResult held;
  Seconds eval;
  fs::path report, compare, model, table;
};

void PrintDemoSummary(const DemoOptions& o, const DemoSummary& d, const std::vector<StageResult>& stages) {
  const auto& ev = d.sparse;
  const auto& cmp = d.mesh;
  std::printf("\nfmv3d demo: %d-frame synthetic orbit (%dx%d) around a %.0f m building\n", o.frames, o.width, o.height,
              d.height);
  std::printf("  %-44s %zu / %d\n", "registered frames", d.registered, o.frames);
  std::printf("  %-44s %.4f %%\n", "camera centre RMSE (of the orbit's extent)", 100 * ev.centre_rmse_fraction);
  std::printf("  %-44s %.4f deg\n", "median relative rotation error", ev.median_rotation_error_deg);
  std::printf("  %-44s %.4f %%\n", "focal length error", 100 * ev.focal_relative_error);
  std::printf("  %-44s %.3f px\n", "mean reprojection error", d.reprojection_px);
  std::printf("  Poisson mesh vs CAD (%% of the building height, %zu vertices measured):\n", cmp.points_measured);
  std::printf("    %-10s %8s %8s %8s %8s %8s\n", "axis", "mean", "sigma", "RMS", "p50", "p90");
  const std::pair<const char*, const align::ErrorStats*> rows[] = {
      {"X", &cmp.x}, {"Y", &cmp.y}, {"Z", &cmp.z}, {"distance", &cmp.total}};
  for (const auto& [name, e] : rows)
    std::printf("    %-10s %8.3f %8.3f %8.3f %8.3f %8.3f\n", name, 100 * e->mean, 100 * e->std, 100 * e->rms,
                100 * e->p50, 100 * e->p90);
  std::printf("  %-44s %.1f %%\n",
              cmp.completeness_from_faces ? "completeness (seen surface within 1% of H, mesh)"
                                          : "completeness (seen surface within 1% of height)",
              100 * cmp.completeness);
  std::printf("  %-44s %.1f dB over %.0f %% of the frame\n", "held-out view PSNR (textured model vs truth)",
              d.held.psnr_db, 100 * d.held.covered_fraction);
  std::printf("  time (s, this run; skipped stages not counted):\n    %-12s %8s %8s\n", "stage", "wall", "CPU");
  Seconds total;
  for (const auto& st : stages)
    if (!st.skipped) {
      std::printf("    %-12s %8.1f %8.1f\n", st.name.c_str(), st.seconds, st.cpu_seconds);
      total.wall += st.seconds;
      total.cpu += st.cpu_seconds;
    }
  std::printf("    %-12s %8.1f %8.1f\n    %-12s %8.1f %8.1f\n", "evaluation", d.eval.wall, d.eval.cpu, "total",
              total.wall + d.eval.wall, total.cpu + d.eval.cpu);
  std::printf("\n  report:  %s\n  compare: %s\n  model:   %s\n  table:   %s\n", d.report.c_str(), d.compare.c_str(),
              d.model.c_str(), d.table.c_str());
}

}  // namespace

nlohmann::json RunDemo(const DemoOptions& o) {
  o.Check();
  core::EnsureDirectory(o.output);
  const fs::path video = o.output / "flight.mp4";
  const fs::path truth_json = o.output / "truth.json";
  if (!fs::exists(video) || !fs::exists(truth_json)) RenderDemoFlight(o);
  const double height = core::ReadJson(truth_json).at("characteristic_length").get<double>();

  const ReconstructOptions r = DemoReconstructOptions(o, video);
  const core::Workspace ws(r.workspace);
  std::vector<StageResult> stages;
  RunReconstruct(r, &stages);
  const auto t_eval = std::chrono::steady_clock::now();
  const double cpu_eval = ProcessCpuSeconds();

  // Accuracy: cameras against the exact truth (similarity by frame name), surfaces against the CAD model.
  DemoSummary d;
  d.height = height;
  const core::Reconstruction truth = io::ReadColmapText(o.output / "truth");
  const core::Reconstruction model = io::ReadColmapText(ws.sparse_dir());
  d.registered = model.images.size();
  d.reprojection_px = model.MeanReprojectionError();
  d.sparse = sfm::EvaluateSparse(model, truth);
  nlohmann::json demo;
  demo["building_height_m"] = height;
  demo["frames"] = o.frames;
  demo["registered"] = d.registered;
  demo["sparse"] = d.sparse.ToJson();
  demo["sparse"]["mean_reprojection_error_px"] = d.reprojection_px;
  // The Poisson mesh against the CAD model, brought into its frame by the camera alignment (+ scaled ICP).
  const io::TexturedMesh cad = BuildingOnly(io::ReadObj(o.output / "scene.obj", /*load_textures=*/false));
  if (cad.faces.empty()) throw Error((o.output / "scene.obj").string() + ": no building faces");
  io::WriteObj(cad, o.output / "cad.obj");
  align::CompareOptions c;
  c.reconstruction = ws.mesh_dir() / "poisson.ply";
  c.cad = o.output / "cad.obj";
  c.length = height;
  c.transform = d.sparse.alignment;
  c.cameras = o.output / "truth";
  c.output_dir = ws.report_dir() / "compare";
  d.mesh = align::CompareToCad(c);
  demo["mesh_vs_cad"] = d.mesh.ToJson();
  // The textured model from a viewpoint the reconstruction never saw, against the true frame there.
  d.held = RenderHeldOut(o.output, ws.mesh_dir() / "textured.obj", d.mesh.transform, synth::SynthOptions().render,
                         o.output / "heldout");
  demo["held_out_view"] = {{"between_frames", d.held.between},
                           {"psnr_db", d.held.psnr_db},
                           {"covered_percent", 100 * d.held.covered_fraction},
                           {"images", (o.output / "heldout").string()}};
  d.eval.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_eval).count();
  d.eval.cpu = ProcessCpuSeconds() - cpu_eval;
  demo["seconds"] = StageTiming(stages, d.eval);
  demo["options"] = {
      {"max_features", o.max_features},           {"pairs", o.sequential_pairs ? "sequential" : "exhaustive"},
      {"pair_overlap", o.pair_overlap},           {"dense_max_size", o.dense_max_size},
      {"dense_sources", o.dense_sources},         {"dense_iterations", o.dense_iterations},
      {"dense_geometric_pass", o.dense_geometric}};
  core::WriteJson(o.output / "demo.json", demo);
  WriteReport(r.workspace);
  d.report = ws.report_dir() / "report.html";
  d.compare = c.output_dir / "compare.html";
  d.model = ws.mesh_dir() / "model.glb";
  d.table = o.output / "demo.json";
  PrintDemoSummary(o, d, stages);
  return demo;
}

}  // namespace fmv3d::pipeline
