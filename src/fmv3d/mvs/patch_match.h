// PatchMatch stereo (after Bleyer et al. 2011, Galliani et al. 2015, Schönberger et al. 2016): one depth and
// one normal per reference pixel, i.e. a small plane, found by
//   1. initialisation: random planes in the depth range, plus planes through the sparse points the view sees
//      (so surfaces grow from the SfM points);
//   2. red–black checkerboard propagation: half the pixels (one colour) try their neighbours' planes while
//      the other half is read-only, so a colour's pixels are updated in parallel and deterministically;
//   3. random refinement: perturbed depth / normal around the current plane, the range shrinking each round.
// A plane is scored by bilaterally weighted NCC (invariant to gain and bias: different exposure or cameras
// still match) between the reference patch and its image under the plane's homography in each source view;
// the best `top_k` source costs are averaged (per-pixel view selection: occluded sources drop out).
// With source depth maps given, a geometric term is added per source (forward–backward reprojection error
// through the source depth map, COLMAP's geometric consistency), which removes most remaining outliers.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "fmv3d/mvs/depth_map.h"
#include "fmv3d/mvs/view.h"

namespace fmv3d::mvs {

struct PatchMatchOptions {
  // Patch: (2·(radius/step) + 1)² samples every `step` pixels, spanning ±(radius/step)·step pixels
  // (5 and 2: 5x5 samples over 9x9 pixels; sparse sampling keeps the support, at a fraction of the cost).
  int window_radius = 5;
  int window_step = 2;
  double sigma_color = 0.2;  // bilateral weight on grey-value difference to the centre (0..1 grey)
  double sigma_spatial = 5;  // bilateral weight on distance to the centre, pixels
  int iterations = 5;        // photometric rounds (red + black each); with coarse_to_fine, at half resolution
  // coarse_to_fine: rounds at full resolution after upsampling the coarse planes. Further rounds lower the cost
  // but do not bring depths closer to the truth (measured on synthetic flights).
  int fine_iterations = 2;
  int geom_iterations = 1;   // rounds of the geometric pass (a second did not bring depths closer)
  int top_k = 3;             // best source costs averaged per pixel
  double geom_weight = 0.3;  // cost per pixel of reprojection error in the geometric pass
  double geom_max_error_px = 3;
  double max_cost = 0.7;       // final filter: pixels whose aggregated 1-NCC stays above are dropped
  bool coarse_to_fine = true;  // first solve at half resolution and upsample (faster convergence)
  int coarse_min_size = 320;   // no coarse level when the view's longer side is below this
  uint64_t seed = 0;
  // The NCC on 8 lanes where the CPU has AVX2 and FMA: the same cost as the 4-lane kernel up to float rounding
  // (the sums are grouped differently), so maps differ from it only where rounding flips a choice.
  bool use_avx2 = true;
  void Check() const;
};

struct PatchMatchInput {
  const View* ref = nullptr;
  std::vector<const View*> sources;
  double depth_min = 0, depth_max = 0;  // camera-frame z range of the reference
  std::vector<Eigen::Vector3d> seeds;   // world points the reference sees (sparse model)
  // Geometric pass: the sources' depth maps (same order as sources; null = no geometric term for it) and
  // the reference's photometric map to start from.
  std::vector<const DepthMap*> source_maps;
  const DepthMap* init = nullptr;
};

struct PatchMatchStats {
  double seconds = 0;
  int valid_pixels = 0;
};

// Whether this build and CPU run the 8-lane NCC (PatchMatchOptions::use_avx2).
bool Avx2KernelAvailable();

// Throws fmv3d::Error when the input is inconsistent (no sources, empty depth range).
DepthMap RunPatchMatch(const PatchMatchInput& input, const PatchMatchOptions& options,
                       PatchMatchStats* stats = nullptr);

}  // namespace fmv3d::mvs
