// TexturedMesh: the triangle mesh with UVs, normals and materials that the renderer draws, synth builds and
// io/obj_io reads and writes (Wavefront OBJ/MTL). World units are metres, z up.
//
// Texture coordinates follow OBJ: (u, v) in [0, 1], v = 0 at the *bottom* row of the texture image, so a
// texel row is (1 - v)·height. Colours are kept in OpenCV order (BGR) in memory; the MTL file's Kd is RGB.
// Triangles are counter-clockwise when seen from outside (the normal (b - a) × (c - a) points outwards).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace fmv3d::io {

struct Material {
  std::string name;
  Eigen::Vector3f diffuse_bgr{0.8f, 0.8f, 0.8f};  // Kd in [0, 1], used when there is no texture
  std::string texture_file;                       // map_Kd, relative to the .mtl; empty when none
  cv::Mat texture;                                // CV_8UC3 BGR, empty when none
};

struct Face {
  int v[3] = {-1, -1, -1};   // vertex indices
  int vt[3] = {-1, -1, -1};  // texture-coordinate indices, -1 when absent
  int vn[3] = {-1, -1, -1};  // normal indices, -1 when absent (the face normal is used)
  int material = -1;         // index into materials, -1 when none
};

struct TexturedMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector2f> uvs;
  std::vector<Eigen::Vector3f> normals;
  std::vector<Face> faces;
  std::vector<Material> materials;

  // Appends another mesh (indices and materials are offset); materials are not merged.
  void Append(const TexturedMesh& other);
  Eigen::AlignedBox3d Bounds() const;
  // Unit normal of face i from its vertices (zero for a degenerate face).
  Eigen::Vector3d FaceNormal(size_t i) const;
  double SurfaceArea() const;
  // Throws fmv3d::Error when an index is out of range.
  void Validate() const;
};

}  // namespace fmv3d::io
