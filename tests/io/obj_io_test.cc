// Wavefront OBJ/MTL (io/obj_io.h): what the reader accepts and the messages of what it rejects, and the written
// files read back exactly, with the atlas pages encoded once for every format.
#include "fmv3d/io/obj_io.h"

#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "fmv3d/core/error.h"
#include "test_util.h"

namespace fmv3d::io {
namespace {

namespace fs = std::filesystem;

fs::path WriteText(const test::TempDir& dir, const std::string& name, const std::string& text) {
  fs::path p = dir / name;
  std::ofstream(p) << text;
  return p;
}

std::string ErrorOf(const fs::path& obj) {
  try {
    ReadObj(obj, false);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(ObjIo, ReadsPolygonsRelativeIndicesMaterialsAndSignedNumbers) {
  const test::TempDir dir("fmv3d-obj");
  WriteText(dir, "m.mtl", "newmtl red\nKd 1 0 0\n\nnewmtl blue\nKd 0 0 1\n");
  const fs::path obj = WriteText(dir, "m.obj",
                                 "# a quad and a triangle\n"
                                 "mtllib m.mtl\n"
                                 "v 0 0 0\nv +1.5 0 0\r\nv 1.5 2 -0\nv 0 2 1e-3 0.5 0.5 0.5\n"
                                 "vt 0 0\nvt 1 0\nvt 1 1\n"
                                 "vn 0 0 1\n"
                                 "usemtl blue\n"
                                 "f 1/1/1 2/2/1 3/3/1 4//1\n"
                                 "\tusemtl  red \n"
                                 "f -4 -3 -1\n");
  const TexturedMesh mesh = ReadObj(obj, false);
  ASSERT_EQ(mesh.vertices.size(), 4U);
  EXPECT_EQ(mesh.vertices[1].x(), 1.5);
  EXPECT_EQ(mesh.vertices[3].z(), 1e-3);  // colours after the position are ignored
  ASSERT_EQ(mesh.faces.size(), 3U);       // the quad fan-triangulated, then the triangle
  EXPECT_EQ(mesh.faces[1].v[0], 0);
  EXPECT_EQ(mesh.faces[1].v[1], 2);
  EXPECT_EQ(mesh.faces[1].v[2], 3);
  EXPECT_EQ(mesh.faces[1].vt[2], -1);  // "4//1": no texture coordinate
  EXPECT_EQ(mesh.faces[1].vn[2], 0);
  EXPECT_EQ(mesh.faces[2].v[0], 0);  // -4 of 4 vertices
  EXPECT_EQ(mesh.faces[2].v[2], 3);
  ASSERT_EQ(mesh.materials.size(), 2U);
  EXPECT_EQ(mesh.materials[mesh.faces[0].material].name, "blue");
  EXPECT_EQ(mesh.materials[mesh.faces[2].material].name, "red");
}

TEST(ObjIo, MalformedLinesAreErrorsNamingTheLine) {
  const test::TempDir dir("fmv3d-obj-bad");
  const std::string three = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  const struct {
    std::string text, message;
  } cases[] = {
      {"v 0 0\n", "m.obj:1: bad vertex"},
      {"v 0 0 inf\n", "m.obj:1: bad vertex"},
      {"v 0 0 1x\n", "m.obj:1: bad vertex"},
      {"vt 0.5\n", "m.obj:1: bad texture coordinate"},
      {"vn 0 nan 1\n", "m.obj:1: bad normal"},
      {three + "f 1 2\n", "m.obj:4: face with fewer than 3 corners"},
      {three + "f 1 2 4\n", "m.obj:4: index 4 out of range"},
      {three + "f 1 2 0\n", "m.obj:4: index 0 out of range"},
      {three + "f 1 2 x\n", "m.obj:4: bad index 'x'"},
      {three + "f 1/1/1/1 2 3\n", "m.obj:4: bad face corner '1/1/1/1'"},
      {three + "vt 0 0\nf /1 2 3\n", "m.obj:5: face corner without a vertex"},
  };
  for (const auto& c : cases) {
    const std::string error = ErrorOf(WriteText(dir, "m.obj", c.text));
    EXPECT_NE(error.find(c.message), std::string::npos) << c.text << " gave: " << error;
  }
}

TEST(ObjIo, WrittenMeshReadsBackExactlyWithItsPagesEncodedOnce) {
  const test::TempDir dir("fmv3d-obj-rt");
  TexturedMesh mesh;
  mesh.vertices = {{0.1, 0.2, 0.3}, {1.0 / 3, -2.0 / 7, 1e-9}, {123456.789012345, 2, 3}};
  mesh.uvs = {{0.1f, 0.2f}, {0.9f, 0.25f}, {0.5f, 0.75f}};
  mesh.normals = {{0, 0, 1}};
  for (int m = 0; m < 2; ++m) {
    Material mat;
    mat.name = "page" + std::to_string(m);
    mat.texture = cv::Mat(64, 96, CV_8UC3);
    cv::randu(mat.texture, 0, 256);
    mesh.materials.push_back(mat);
    Face f;
    for (int k = 0; k < 3; ++k) f.v[k] = f.vt[k] = k, f.vn[k] = 0;
    f.material = m;
    mesh.faces.push_back(f);
  }
  const EncodedTextures pages = EncodeTextures(mesh);
  ASSERT_EQ(pages.size(), 2U);
  WriteObj(mesh, dir / "model.obj", pages);
  const TexturedMesh back = ReadObj(dir / "model.obj", true);
  ASSERT_EQ(back.vertices.size(), 3U);
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(back.vertices[i], mesh.vertices[i]) << i;  // 17 digits: exact
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(back.uvs[i], mesh.uvs[i]) << i;
  ASSERT_EQ(back.faces.size(), 2U);
  ASSERT_EQ(back.materials.size(), 2U);
  for (int m = 0; m < 2; ++m) {
    EXPECT_EQ(back.faces[m].material, m);
    ASSERT_EQ(back.materials[m].texture.size(), mesh.materials[m].texture.size());
    EXPECT_EQ(cv::norm(back.materials[m].texture, mesh.materials[m].texture, cv::NORM_INF), 0.0);
  }
  // The pages on disk are the encoded bytes, and writing without them gives the same files.
  WriteObj(mesh, dir / "again.obj");
  for (int m = 0; m < 2; ++m) {
    std::ifstream a(dir / ("model_page" + std::to_string(m) + ".png"), std::ios::binary);
    std::ifstream b(dir / ("again_page" + std::to_string(m) + ".png"), std::ios::binary);
    const std::string sa((std::istreambuf_iterator<char>(a)), {}), sb((std::istreambuf_iterator<char>(b)), {});
    EXPECT_EQ(sa, std::string(pages[m].begin(), pages[m].end()));
    EXPECT_EQ(sa, sb);
  }
  EXPECT_THROW(WriteObj(mesh, dir / "short.obj", EncodedTextures(1)), Error);
}

}  // namespace
}  // namespace fmv3d::io
