#include "fmv3d/surface/texture_stage.h"

#include <spdlog/spdlog.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <chrono>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/mvs/view.h"
#include "fmv3d/mvs/view_selection.h"
#include "fmv3d/surface/gltf_writer.h"

namespace fmv3d::surface {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::vector<TextureView> LoadTextureViews(const core::Reconstruction& model, const fs::path& frames_dir) {
  std::vector<TextureView> views;
  for (const auto& [id, im] : model.images) {
    TextureView v;
    v.image_id = id;
    v.name = im.name;
    v.camera = model.cameras.at(im.camera_id);
    v.pose = im.pose;
    views.push_back(std::move(v));
  }
  for (const auto& v : views)
    if (!fs::exists(frames_dir / v.name)) throw Error((frames_dir / v.name).string() + ": registered frame is missing");
  return views;
}

cv::Mat LoadTextureFrame(const TextureView& v, const fs::path& frames_dir) {
  cv::Mat image = io::ReadImage(frames_dir / v.name);
  if (image.cols != v.camera.width || image.rows != v.camera.height)
    throw Error((frames_dir / v.name).string() + ": image is " + std::to_string(image.cols) + "x" +
                std::to_string(image.rows) + " but its camera is " + std::to_string(v.camera.width) + "x" +
                std::to_string(v.camera.height));
  return image;
}

namespace {

nlohmann::json ToJson(const ViewSelectionStats& s) {
  return {{"faces", s.faces},
          {"views", s.views},
          {"candidates", s.candidates},
          {"mean_candidates_per_face", s.mean_candidates_per_face},
          {"inconsistent_candidates", s.inconsistent_candidates},
          {"labelled_faces", s.labelled_faces},
          {"labelled_share", s.labelled_share},
          {"smoothing_changes", s.smoothing_changes},
          {"seconds_visibility", s.seconds_visibility},
          {"seconds", s.seconds}};
}

nlohmann::json ToJson(const AtlasStats& s) {
  nlohmann::json j = {{"patches", s.patches},       {"charts", s.charts}, {"unseen_faces", s.unseen_faces},
                      {"seam_edges", s.seam_edges}, {"pages", s.pages},   {"atlas_fill", s.atlas_fill},
                      {"seconds", s.seconds}};
  if (s.max_gain_deviation) j["max_gain_deviation"] = *s.max_gain_deviation;
  j["page_size"] = nlohmann::json::array();
  for (const auto& [w, h] : s.page_size) j["page_size"].push_back({w, h});
  return j;
}

}  // namespace

TexturedModel TextureMesh(const ColoredMesh& mesh, const std::vector<TextureView>& views, FrameWindow& frames,
                          const TextureStageOptions& options) {
  options.Check();
  if (mesh.empty()) throw Error("texture: the mesh has no faces");
  if (views.empty()) throw Error("texture: no registered views");
  if (frames.frames() != views.size()) throw Error("texture: the frame window does not match the views");
  const auto start = Clock::now();
  ColoredMesh m = mesh;
  if (m.normals.size() != m.vertices.size()) m.ComputeVertexNormals();
  const std::vector<Eigen::Vector3i> adjacency = FaceAdjacency(m.triangles);
  const ViewSelection selection = SelectViews(m, adjacency, views, frames, options.selection);
  const auto atlas_start = Clock::now();
  TexturedModel model = BuildTextureAtlas(m, adjacency, views, frames, selection.labels, options.atlas);
  model.atlas.seconds = std::chrono::duration<double>(Clock::now() - atlas_start).count();
  model.selection = selection.stats;
  model.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return model;
}

TexturedModel TextureMesh(const ColoredMesh& mesh, const std::vector<TextureView>& views,
                          const TextureStageOptions& options) {
  FrameWindow frames(
      views.size(), [&](size_t i) { return views[i].image; }, views.size());
  return TextureMesh(mesh, views, frames, options);
}

nlohmann::json RunTextureStage(const core::Workspace& workspace, const TextureStageOptions& options) {
  options.Check();
  const auto start = Clock::now();
  const std::string ws = workspace.name();
  if (!fs::exists(workspace.root())) throw Error(ws + ": no such workspace folder");
  const fs::path mesh_path = workspace.mesh_dir() / "poisson.ply";
  const fs::path sparse = workspace.sparse_dir();
  if (!fs::exists(sparse / "images.txt"))
    throw Error(ws + ": no sparse/images.txt — run `fmv3d sparse " + ws + "` first");
  if (!fs::exists(mesh_path)) throw Error(ws + ": no mesh/poisson.ply — run `fmv3d mesh " + ws + "` first");
  const ColoredMesh mesh = ReadMeshPly(mesh_path);
  core::Reconstruction model = io::ReadColmapText(sparse);
  if (model.images.empty()) throw Error((sparse / "images.txt").string() + ": no registered images");
  const size_t registered = model.images.size();
  if (options.view_coverage > 0) {
    std::map<uint32_t, mvs::ViewGeometry> geoms;
    std::vector<uint32_t> ids;
    for (const auto& [id, im] : model.images) {
      geoms[id] = mvs::MakeViewGeometry(model, id, 0);
      ids.push_back(id);
    }
    mvs::ReferenceCoverOptions cover;
    cover.coverage = options.view_coverage;
    const auto keep = mvs::SelectReferenceViews(model, geoms, ids, cover);
    for (auto it = model.images.begin(); it != model.images.end();)
      it = std::binary_search(keep.begin(), keep.end(), it->first) ? std::next(it) : model.images.erase(it);
    spdlog::info("texture: colour from {} of {} views (each sparse point in {} of them)", model.images.size(),
                 registered, options.view_coverage);
  }
  const fs::path frames_dir = workspace.frames_dir();
  const std::vector<TextureView> views = LoadTextureViews(model, frames_dir);
  double frame_bytes = 1;
  for (const auto& v : views) frame_bytes = std::max(frame_bytes, 3.0 * v.camera.width * v.camera.height);
  FrameWindow frames(
      views.size(), [&](size_t i) { return LoadTextureFrame(views[i], frames_dir); },
      ChooseFrameWindow(views.size(), frame_bytes, options.max_memory_mb));
  const double load_seconds = std::chrono::duration<double>(Clock::now() - start).count();

  TexturedModel textured = TextureMesh(mesh, views, frames, options);
  frames.Release();

  const auto write_start = Clock::now();
  const fs::path dir = workspace.mesh_dir();
  // Atlas pages of an earlier run with more pages must not linger beside the new OBJ.
  for (size_t p = textured.mesh.materials.size();; ++p) {
    const fs::path old = dir / ("textured_atlas_" + std::to_string(p) + ".png");
    if (!fs::exists(old)) break;
    fs::remove(old);
  }
  // The atlas pages are encoded once for the OBJ and the glTF; the three files are written side by side.
  const io::EncodedTextures pages = io::EncodeTextures(textured.mesh);
  tbb::task_group writers;
  writers.run([&] { io::WriteObj(textured.mesh, dir / "textured.obj", pages); });
  writers.run([&] { WriteGlb(textured.mesh, dir / "model.glb", &pages); });
  writers.run([&] {
    ColoredMesh colored;
    colored.vertices = textured.mesh.vertices;
    colored.normals = textured.mesh.normals;
    colored.colors = textured.vertex_colors;
    colored.triangles.reserve(textured.mesh.faces.size());
    for (const auto& f : textured.mesh.faces) colored.triangles.emplace_back(f.v[0], f.v[1], f.v[2]);
    WriteMeshPly(colored, dir / "textured.ply");
  });
  writers.wait();

  nlohmann::json report = {
      {"selection", ToJson(textured.selection)}, {"atlas", ToJson(textured.atlas)}, {"seconds", textured.seconds}};
  report["input"] = "mesh/poisson.ply";
  report["outputs"] = {"mesh/textured.obj", "mesh/textured.mtl", "mesh/model.glb", "mesh/textured.ply"};
  for (const auto& material : textured.mesh.materials)
    report["outputs"].push_back("mesh/textured_" + material.name + ".png");
  report["views"] = views.size();
  report["registered_views"] = registered;
  report["faces"] = textured.mesh.faces.size();
  report["memory"] = {{"max_memory_mb", options.max_memory_mb},
                      {"frame_window", frames.capacity()},
                      {"frame_loads", frames.loads()},
                      {"peak_frames_held", frames.peak_resident()}};
  report["seconds"] = {{"load", load_seconds},
                       {"texturing", textured.seconds},
                       {"write", std::chrono::duration<double>(Clock::now() - write_start).count()},
                       {"total", std::chrono::duration<double>(Clock::now() - start).count()}};
  core::EnsureDirectory(workspace.report_dir());
  core::WriteJson(workspace.report_dir() / "texture.json", report);
  spdlog::info("texture: {} faces from {} views → {} ({} frame loads, at most {} frames held)",
               textured.mesh.faces.size(), views.size(), (dir / "textured.obj").string(), frames.loads(),
               frames.peak_resident());
  return report;
}

}  // namespace fmv3d::surface
