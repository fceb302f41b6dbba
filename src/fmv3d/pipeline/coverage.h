// Coverage of every registered view by the reconstruction: the share of the view's non-sky pixels that the
// mesh and the dense cloud cover, seen from that view — how much of what the cameras saw the model holds.
//
//   mesh:   the mesh rendered through the view's camera (render/, both sides of every face): a pixel is
//           covered when a face is seen through it;
//   dense:  every point projected into the view as a disc of its footprint (the cloud's median spacing at the
//           point's depth, at least one pixel), hidden when the mesh is seen clearly in front of it;
//   sky:    SkyMask of the frame, less what the mesh covers (a surface in front of a smooth bright backdrop is
//           never sky). Sky is left out of the denominator: nothing there is to reconstruct.
// Views are evaluated at a working size (longer side `max_size`), which is enough for shares of pixels.
#pragma once

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fmv3d/core/camera.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/io/mesh.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::render {
class Renderer;
}

namespace fmv3d::pipeline {

// Sky: pixels connected to the top border through smooth (grey gradient below `max_gradient`, 0..1 grey per
// pixel after a 5x5 blur), bright (grey ≥ min_brightness) and not reddish (blue ≥ red − 16) pixels, the way
// sky, haze and overcast look above a skyline. A frame without such a region has no sky (nadir views).
// CV_8U, 255 = sky. `bgr` is CV_8UC3.
cv::Mat SkyMask(const cv::Mat& bgr, double max_gradient = 0.012, double min_brightness = 0.45);

struct CoverageOptions {
  int max_size = 480;   // working size of a view, longer side, pixels
  int worst_views = 3;  // views drawn for the report (lowest mesh coverage, else dense)
  void Check() const;
};

struct ViewCoverage {
  uint32_t image_id = 0;
  std::string name;
  size_t non_sky_pixels = 0, sky_pixels = 0;
  double mesh = -1, dense = -1;  // shares of the non-sky pixels; -1 when there is no mesh / cloud
};

struct CoverageMaps {
  cv::Mat sky, mesh, dense;  // CV_8U, 255 = sky / covered; empty when there is no mesh / cloud
};

// One view: `frame` is the registered frame (any size; resized to the camera's working size), `camera` and
// `pose` the view's, `mesh`/`cloud` may be null. `point_spacing` is the cloud's median spacing (for the
// footprint). `maps` (optional) receives the masks.
ViewCoverage ComputeViewCoverage(const cv::Mat& frame, const core::Camera& camera, const core::Pose& pose,
                                 const io::TexturedMesh* mesh, const io::OrientedPointCloud* cloud,
                                 double point_spacing, CoverageMaps* maps = nullptr);
// The same through a renderer of the mesh that the caller builds once for many views (null: no mesh). Only depth
// is rendered, so a renderer of the mesh without its textures is enough.
ViewCoverage ComputeViewCoverageWith(const cv::Mat& frame, const core::Camera& camera, const core::Pose& pose,
                                     const render::Renderer* mesh, const io::OrientedPointCloud* cloud,
                                     double point_spacing, CoverageMaps* maps = nullptr);

struct CoverageReport {
  std::vector<ViewCoverage> views;  // by image id
  double median_mesh = -1, median_dense = -1;
  struct Picture {
    std::string file;  // relative to the report folder
    size_t view = 0;   // index into views
  };
  std::vector<Picture> pictures;  // worst first
  nlohmann::json ToJson() const;
};

// Every registered view of the workspace (WS/sparse, WS/frames, WS/mesh/poisson.ply or textured.obj,
// WS/dense/fused.ply); writes the worst views as side-by-side pictures (frame | mesh from the view |
// coverage: red = non-sky not covered by the mesh, blue = sky) to WS/report/coverage/. Throws fmv3d::Error
// when the workspace has no sparse model.
CoverageReport ComputeWorkspaceCoverage(const std::filesystem::path& workspace, const CoverageOptions& options);

}  // namespace fmv3d::pipeline
