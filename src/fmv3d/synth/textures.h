// Procedural textures for synthetic scenes: aerial-looking ground (fields, meadows, forest, roads, rocks,
// grain at every scale, never tiled), building façades (storeys of windows, each one different, stains) and
// roofs (tile courses or gravel). Deterministic functions of their inputs; generated in parallel.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <vector>

namespace fmv3d::synth {

// Ground texture covering `extent` (world x right, y up = north at the top row), size_px × size_px texels.
// `height(x, y)` lets steep slopes turn rocky; `paved` marks places (around buildings) drawn as pavement.
cv::Mat GroundTexture(int size_px, const Eigen::AlignedBox2d& extent, uint64_t seed,
                      const std::function<double(double, double)>& height,
                      const std::function<bool(double, double)>& paved);

// Low-contrast ground as nadir surveys meet it over sand, dry grass and water: wind ripples and faint grain on
// sand, soft tufts on grass, almost uniform water (ponds where `wetness` of the place is high). Contrast is a
// few digital numbers, so a detector with a fixed contrast threshold finds few, clustered keypoints.
cv::Mat LowTextureGround(int size_px, const Eigen::AlignedBox2d& extent, uint64_t seed);

// Façade strip: the building's walls unrolled side by side (u = distance along the perimeter), from the
// bottom of the walls (v = 0) to `total_height` (v = 1). Windows are drawn on each wall between
// `ground_offset` (the wall's base above its bottom edge) and `eave_height` (relative to the base).
struct FacadeSpec {
  std::vector<double> wall_lengths;  // metres, in perimeter order
  double total_height = 30;          // metres covered by the texture (bottom of wall to ridge)
  double ground_offset = 0;          // where the ground floor starts above the bottom edge
  double eave_height = 24;           // top of the storeys, relative to the ground floor
  double floor_height = 3;
  double texels_per_metre = 30;
  uint64_t seed = 1;
};
cv::Mat FacadeTexture(const FacadeSpec& spec);

// Roof texture of width_m × height_m metres; pitched: tile courses along u; flat: gravel with fixtures.
cv::Mat RoofTexture(double width_m, double height_m, bool pitched, double texels_per_metre, uint64_t seed);

}  // namespace fmv3d::synth
