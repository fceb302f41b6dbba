// `fmv3d texture` on a synthetic workspace: the textured Poisson mesh rendered from a held-out true camera
// must reproduce the real frame; a view spoiled by an occluder must not be used; the outputs (OBJ + atlas
// PNGs, GLB, PLY) must open.
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include "fmv3d/surface/texture_stage.h"

#include <gtest/gtest.h>
#include <tiny_gltf.h>  // declarations only: the implementation lives in fmv3d_surface

#include <fstream>
#include <iterator>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/render/renderer.h"
#include "fmv3d/surface/gltf_writer.h"
#include "fmv3d/surface/mesh_stage.h"
#include "fmv3d/surface/synthetic_cloud.h"
#include "synthetic_flight.h"
#include "test_util.h"

namespace fmv3d::surface {
namespace {

namespace fs = std::filesystem;

// A workspace with a Poisson mesh from a slightly noisy cloud (frame 6 is not in its sparse model), made
// once for the binary's processes and copied for each test, since tests may spoil its frames.
void PrepareMeshed(const fs::path& ws) {
  static const fs::path meshed = test::SharedFixture("texture-meshed-workspace", [](const fs::path& dir) {
    SyntheticCloudOptions o;
    o.spacing = 0.15;
    o.position_noise = 0.02;
    o.region = Eigen::AlignedBox3d(Eigen::Vector3d(-18, -18, -3), Eigen::Vector3d(18, 18, 35));
    PrepareSyntheticWorkspace(testing::Flight().synth_dir, dir, o, {testing::kHeldOut});
    RunMeshStage(dir, MeshStageOptions{});
  });
  fs::copy(meshed, ws, fs::copy_options::recursive | fs::copy_options::overwrite_existing);
}

struct Comparison {
  double psnr = 0;
  double covered = 0;  // share of the frame the model covers
};

// Renders the textured OBJ from the true pose of `name` and compares with the frame over the covered pixels.
Comparison CompareWithFrame(const fs::path& ws, const std::string& name, const cv::Mat& frame) {
  const auto& flight = testing::Flight();
  const core::Reconstruction truth = io::ReadColmapText(flight.synth_dir / "truth");
  const core::Image* im = truth.FindImageByName(name);
  EXPECT_NE(im, nullptr);
  const io::TexturedMesh textured = io::ReadObj(ws / "mesh/textured.obj");
  const render::Renderer renderer(textured);
  render::RenderOptions ro;
  ro.shading = false;  // the texture already holds the lit colours
  const render::RenderResult r = renderer.Render(truth.cameras.at(im->camera_id), im->pose, ro);
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x) {
      if (r.face.at<int32_t>(y, x) < 0) continue;
      const cv::Vec3b& a = r.image.at<cv::Vec3b>(y, x);
      const cv::Vec3b& b = frame.at<cv::Vec3b>(y, x);
      for (int c = 0; c < 3; ++c) se += (a[c] - b[c]) * (a[c] - b[c]);
      n += 3;
    }
  Comparison cmp;
  cmp.covered = static_cast<double>(n) / 3 / (frame.rows * frame.cols);  // n counts 3 channels per pixel
  cmp.psnr = n ? 10 * std::log10(255.0 * 255.0 / (se / n)) : 0;
  return cmp;
}

TEST(TextureStage, HeldOutViewIsReproduced) {
  test::TempDir ws("fmv3d-texture");
  PrepareMeshed(ws.path());
  const nlohmann::json report = RunTextureStage(ws.path(), TextureStageOptions{});
  for (const char* f : {"mesh/textured.obj", "mesh/textured.mtl", "mesh/textured_atlas_0.png", "mesh/model.glb",
                        "mesh/textured.ply", "report/texture.json"})
    EXPECT_TRUE(fs::exists(ws / f)) << f;
  EXPECT_GT(report["selection"]["labelled_share"].get<double>(), 0.9);
  const cv::Mat page = cv::imread((ws / "mesh/textured_atlas_0.png").string());
  ASSERT_FALSE(page.empty());
  EXPECT_LE(page.cols, 4096);
  EXPECT_LE(page.rows, 4096);

  const cv::Mat frame = cv::imread((testing::Flight().synth_dir / "frames" / testing::kHeldOut).string());
  const Comparison cmp = CompareWithFrame(ws.path(), testing::kHeldOut, frame);
  RecordProperty("held_out_psnr", std::to_string(cmp.psnr));
  EXPECT_GT(cmp.covered, 0.05);  // the building and its apron (the cloud covers ±18 m) in a wide view
  EXPECT_GE(cmp.psnr, 25.0);

  // The vertex-coloured PLY agrees with the texture: same faces, colours present.
  const ColoredMesh colored = ReadMeshPly(ws / "mesh/textured.ply");
  EXPECT_EQ(colored.triangles.size(), report["faces"].get<size_t>());
  EXPECT_EQ(colored.colors.size(), colored.vertices.size());
}

// The per-face candidate cap (memory on long videos) keeps the best views: with 3 per face instead of every
// view that sees the face, the held-out view is reproduced as well.
TEST(TextureStage, CappedCandidatesKeepTheBestViews) {
  double psnr[2];
  double mean_candidates[2];
  for (int capped = 0; capped < 2; ++capped) {
    test::TempDir ws("fmv3d-texture");
    PrepareMeshed(ws.path());
    TextureStageOptions o;
    o.selection.max_candidates_per_face = capped ? 3 : 255;
    const nlohmann::json report = RunTextureStage(ws.path(), o);
    mean_candidates[capped] = report["selection"]["mean_candidates_per_face"].get<double>();
    const cv::Mat frame = cv::imread((testing::Flight().synth_dir / "frames" / testing::kHeldOut).string());
    psnr[capped] = CompareWithFrame(ws.path(), testing::kHeldOut, frame).psnr;
  }
  EXPECT_GT(mean_candidates[0], 4.0);  // the cap binds
  EXPECT_LE(mean_candidates[1], 3.0);
  EXPECT_GE(psnr[1], psnr[0] - 0.5) << "uncapped " << psnr[0] << " dB";
}

TEST(TextureStage, OccludedViewIsNotUsed) {
  test::TempDir ws("fmv3d-texture");
  PrepareMeshed(ws.path());
  // Paint a magenta "truck" over the building in one frame.
  const std::string spoiled = "flight-000003.png";
  const fs::path path = ws / "frames" / spoiled;
  cv::Mat img = cv::imread(path.string());
  const cv::Rect box(img.cols * 3 / 8, img.rows * 3 / 8, img.cols / 4, img.rows / 4);
  img(box).setTo(cv::Scalar(255, 0, 255));
  ASSERT_TRUE(cv::imwrite(path.string(), img));
  const nlohmann::json report = RunTextureStage(ws.path(), TextureStageOptions{});
  EXPECT_GT(report["selection"]["inconsistent_candidates"].get<size_t>(), 0u);
  // Rendered from the spoiled view, the box must show the scene (the original frame), not magenta.
  const io::TexturedMesh textured = io::ReadObj(ws / "mesh/textured.obj");
  const core::Reconstruction model = io::ReadColmapText(ws / "sparse");
  const core::Image* im = model.FindImageByName(spoiled);
  ASSERT_NE(im, nullptr);
  const render::Renderer renderer(textured);
  render::RenderOptions ro;
  ro.shading = false;
  const render::RenderResult r = renderer.Render(model.cameras.at(im->camera_id), im->pose, ro);
  int magenta = 0, covered = 0;
  for (int y = box.y; y < box.br().y; ++y)
    for (int x = box.x; x < box.br().x; ++x) {
      if (r.face.at<int32_t>(y, x) < 0) continue;
      ++covered;
      const cv::Vec3b p = r.image.at<cv::Vec3b>(y, x);
      magenta += p[0] > 200 && p[1] < 80 && p[2] > 200;
    }
  ASSERT_GT(covered, box.area() / 5);  // the building and the ground around it
  EXPECT_LT(magenta, covered / 50) << magenta << " of " << covered << " pixels magenta";
}

TEST(TextureStage, GlbHoldsTheMeshAndItsPages) {
  test::TempDir ws("fmv3d-texture");
  PrepareMeshed(ws.path());
  const nlohmann::json report = RunTextureStage(ws.path(), TextureStageOptions{});
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(
      [](tinygltf::Image* image, const int, std::string*, std::string*, int, int, const unsigned char* bytes, int size,
         void*) {
        const cv::Mat png = cv::imdecode(cv::Mat(1, size, CV_8U, const_cast<unsigned char*>(bytes)), cv::IMREAD_COLOR);
        image->width = png.cols;
        image->height = png.rows;
        return !png.empty();
      },
      nullptr);
  tinygltf::Model model;
  std::string err, warn;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &err, &warn, (ws / "mesh/model.glb").string())) << err;
  ASSERT_EQ(model.meshes.size(), 1u);
  size_t indices = 0;
  for (const auto& prim : model.meshes[0].primitives) {
    indices += model.accessors[prim.indices].count;
    EXPECT_TRUE(prim.attributes.count("TEXCOORD_0"));
    EXPECT_TRUE(prim.attributes.count("NORMAL"));
  }
  EXPECT_EQ(indices, 3 * report["faces"].get<size_t>());
  EXPECT_EQ(model.images.size(), report["atlas"]["pages"].get<size_t>());
  for (const auto& img : model.images) EXPECT_GT(img.width, 0);

  // glTF is +y up: the GLB's bounds are the OBJ's z-up bounds turned (x, y, z) -> (x, z, -y).
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& prim : model.meshes[0].primitives) {
    const auto& a = model.accessors[prim.attributes.at("POSITION")];
    ASSERT_EQ(a.minValues.size(), 3u);
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], a.minValues[k]), hi[k] = std::max(hi[k], a.maxValues[k]);
  }
  const io::TexturedMesh obj = io::ReadObj(ws / "mesh/textured.obj", false);
  Eigen::Vector3d olo = Eigen::Vector3d::Constant(1e300), ohi = -olo;
  for (const auto& v : obj.vertices) olo = olo.cwiseMin(v), ohi = ohi.cwiseMax(v);
  const double tol = 1e-3 * (ohi - olo).norm();
  EXPECT_NEAR(lo.x(), olo.x(), tol);
  EXPECT_NEAR(hi.x(), ohi.x(), tol);
  EXPECT_NEAR(lo.y(), olo.z(), tol);  // glTF up = our up
  EXPECT_NEAR(hi.y(), ohi.z(), tol);
  EXPECT_NEAR(lo.z(), -ohi.y(), tol);
  EXPECT_NEAR(hi.z(), -olo.y(), tol);
}

TEST(TextureStage, CliSplitsTheAtlasIntoSmallPages) {
  test::TempDir ws("fmv3d-texture");
  PrepareMeshed(ws.path());
  const auto r = test::RunCli("-q texture " + ws.path().string() + " --page-size 256");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json report = core::ReadJson(ws / "report/texture.json");
  const int pages = report["atlas"]["pages"].get<int>();
  EXPECT_GT(pages, 1);
  const std::string mtl = core::ReadTextFile(ws / "mesh/textured.mtl");
  for (int p = 0; p < pages; ++p) {
    const std::string name = "textured_atlas_" + std::to_string(p) + ".png";
    EXPECT_NE(mtl.find(name), std::string::npos) << name;
    const cv::Mat page = cv::imread((ws / "mesh" / name).string());
    ASSERT_FALSE(page.empty()) << name;
    EXPECT_LE(page.cols, 256);
    EXPECT_LE(page.rows, 256);
  }
  // Every face is still textured from the pages it names.
  const io::TexturedMesh mesh = io::ReadObj(ws / "mesh/textured.obj");
  EXPECT_EQ(mesh.materials.size(), static_cast<size_t>(pages));
  for (const auto& f : mesh.faces) ASSERT_TRUE(f.material >= 0 && f.material < pages);
  EXPECT_EQ(test::RunCli("texture " + ws.path().string() + " --page-size 1000").exit_code, 1);
}

std::string FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in) << path;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Frames decoded on demand in a one-frame window (each decoded again by the second pass) give the same files,
// to the byte, as every frame held at once.
TEST(TextureStage, OneFrameWindowGivesTheSameFiles) {
  test::TempDir all("fmv3d-texture"), one("fmv3d-texture");
  PrepareMeshed(all.path());
  PrepareMeshed(one.path());
  const nlohmann::json wide = RunTextureStage(all.path(), TextureStageOptions{});
  const auto r = test::RunCli("-q texture " + one.path().string() + " --max-memory 0.5");  // a frame is 0.37 MB
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json narrow = core::ReadJson(one / "report/texture.json");
  const size_t views = wide["views"].get<size_t>();
  EXPECT_EQ(wide["memory"]["frame_window"].get<size_t>(), views);
  EXPECT_EQ(wide["memory"]["frame_loads"].get<size_t>(), views);
  EXPECT_EQ(narrow["memory"]["frame_window"].get<size_t>(), 1u);
  EXPECT_EQ(narrow["memory"]["peak_frames_held"].get<size_t>(), 1u);
  // Two passes (visibility; seam colours and chart copies): each frame decoded at most twice.
  EXPECT_GT(narrow["memory"]["frame_loads"].get<size_t>(), views);
  EXPECT_LE(narrow["memory"]["frame_loads"].get<size_t>(), 2 * views);
  std::vector<std::string> files = {"mesh/textured.obj", "mesh/textured.mtl", "mesh/model.glb", "mesh/textured.ply"};
  for (int p = 0; p < wide["atlas"]["pages"].get<int>(); ++p)
    files.push_back("mesh/textured_atlas_" + std::to_string(p) + ".png");
  for (const auto& f : files) EXPECT_TRUE(FileBytes(all / f) == FileBytes(one / f)) << f << " differs";
}

TEST(TextureStage, MissingInputsNameTheCommand) {
  test::TempDir ws("fmv3d-texture");
  try {
    RunTextureStage(ws.path(), TextureStageOptions{});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fmv3d sparse"), std::string::npos) << e.what();
  }
  core::EnsureDirectory(ws / "sparse");
  io::WriteColmapText(io::ReadColmapText(testing::Flight().synth_dir / "truth"), ws / "sparse");
  try {
    RunTextureStage(ws.path(), TextureStageOptions{});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fmv3d mesh"), std::string::npos) << e.what();
  }
  const auto r = test::RunCli("texture " + ws.path().string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("fmv3d mesh"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace fmv3d::surface
