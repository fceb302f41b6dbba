// CPU rasteriser: draws a textured triangle mesh through an fmv3d camera (pinhole + Brown–Conrady lens)
// and returns the image, a depth map and a face-index map.
//
// How it stays exact. Every triangle's plane is kept as the 3x3 matrix M = [V0 V1 V2]⁻¹ of its camera-frame
// corners: for the viewing ray d = (x, y, 1) of normalised coordinates, b = M·d / (1ᵀM·d) are the
// perspective-correct barycentrics of the point the ray hits and z = 1 / (1ᵀM·d) its depth. The z-buffer
// pass only decides *which* face is seen: it rasterises the faces into an undistorted pinhole "visibility"
// raster with S×S samples per output pixel (supersampling). Colour and depth are then computed from the
// exact ray of each output pixel (or sub-sample): d = camera.Unproject(pixel), so a 3D point X is drawn
// exactly at camera.Project(pose.Transform(X)), lens distortion included, with no resampling of pixels.
//
// Pixels whose S×S samples all see one face are shaded once at the pixel centre (texture filtered over
// the pixel footprint with trilinear mip-mapping); pixels on an edge shade every sample and average them.
// Shading is Lambertian with a sun direction and ambient light, times an exposure gain, plus optional
// Gaussian sensor noise (deterministic for a seed). Faces without texture use their material's Kd.
//
// Conventions: pixel coordinates as in core/camera.h (pixel centre at +0.5). The image is CV_8UC3 in BGR
// (OpenCV) order. depth is CV_32F: the camera-frame z (metres along the optical axis, not the ray length)
// of the surface seen through the pixel centre, 0 where nothing is seen (sky). face is CV_32S: the index
// of that face in the mesh, -1 where nothing is seen.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/render/texture.h"

namespace fmv3d::render {

struct RenderOptions {
  int supersample = 2;            // visibility samples per pixel along each axis (1..4)
  double sun_azimuth_deg = 135;   // clockwise from +y (north) towards +x (east)
  double sun_elevation_deg = 50;  // above the horizon
  double ambient = 0.4;           // share of light that is not direct sun (sky light)
  double exposure = 1.0;          // gain on the shaded colour; 1 = a flat sunlit surface shows its albedo
  double noise_sigma = 0;         // Gaussian sensor noise, digital numbers (0..255 scale)
  uint64_t noise_seed = 0;        // noise differs for each seed (and should differ for each frame)
  bool cull_backfaces = true;     // skip faces seen from behind (meshes must be wound outwards)
  bool shading = true;            // false: plain albedo (no sun/ambient), handy for tests
  double near_plane = 0.05;       // metres; geometry closer than this to the camera is clipped
  // Throws fmv3d::Error naming the bad field.
  void Check() const;
  // Unit vector towards the sun in the world frame (z up).
  Eigen::Vector3d SunDirection() const;
};

struct RenderResult {
  cv::Mat image;  // CV_8UC3, BGR
  cv::Mat depth;  // CV_32F, camera-frame z through the pixel centre; 0 = nothing
  cv::Mat face;   // CV_32S, face index through the pixel centre; -1 = nothing
};

namespace detail {
struct ShadePlane;  // a face's texture and light as planes in the viewing ray (renderer.cc)
}

class Renderer {
 public:
  // The mesh must outlive the renderer. Textures are mip-mapped once here.
  explicit Renderer(const io::TexturedMesh& mesh);
  ~Renderer();

  RenderResult Render(const core::Camera& camera, const core::Pose& pose, const RenderOptions& options) const;

  const io::TexturedMesh& mesh() const { return mesh_; }

 private:
  struct RayTable;  // per-camera normalised rays of all pixels and samples (cached for distorted lenses)
  struct Scratch;   // per-thread buffers of one frame: faces set up, visibility raster
  std::shared_ptr<const RayTable> Rays(const core::Camera& camera, int supersample) const;
  void PrepareFaces(const RayTable& rt, const core::Pose& pose, const RenderOptions& options, Scratch& sc) const;
  detail::ShadePlane MakeShadePlane(size_t f, const Eigen::Matrix3d& M, const Eigen::Vector3d& m, double side,
                                    const RenderOptions& options, const Eigen::Vector3d& sun, double light_gain) const;
  static void RasteriseVisibility(const RayTable& rt, Scratch& sc);
  static void PixelSampleFaces(const RayTable& rt, const Scratch& sc, int i, int j, int32_t* ids);
  Eigen::Vector3f ShadeRay(const detail::ShadePlane& sp, int f, const Eigen::Vector3d& d, double inv_fx, double inv_fy,
                           float exposure) const;
  void ShadePixels(const core::Camera& camera, const core::Pose& pose, const RayTable& rt, const Scratch& sc,
                   const RenderOptions& options, RenderResult& out) const;

  const io::TexturedMesh& mesh_;
  std::vector<MipTexture> textures_;  // per material (empty when it has no texture)
  std::vector<Eigen::Vector3d> face_normals_;
  mutable std::mutex cache_mutex_;
  mutable std::shared_ptr<const RayTable> ray_cache_;
};

}  // namespace fmv3d::render
