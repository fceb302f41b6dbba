// Texturing, step 2: from per-face view labels (view_selection.h) to a textured mesh with atlas pages.
//
//   Patches   connected faces with the same view. Each patch's faces keep the image coordinates their
//             vertices project to in that view (lens distortion included), so the atlas holds the original
//             pixels, not a resampling of them.
//   Charts    the image rectangles (plus `margin` texels, so bilinear and mip-map filtering do not bleed in
//             a neighbour) of the patches of one view, merged where they overlap: an image region is copied
//             once however many patches it serves.
//   Colour    light adjustment across seams: real cameras change exposure and white balance between frames,
//             so each view gets one gain per channel, chosen (least squares in log colour, pulled towards 1)
//             so that the two views on either side of every seam agree on the seam's colour.
//   Packing   charts sorted by height on shelves, pages of at most `max_page_size`² texels (power-of-two
//             sides). Faces no view sees get a small flat block in their vertex colour.
#pragma once

#include <optional>
#include <utility>
#include <vector>

#include "fmv3d/io/mesh.h"
#include "fmv3d/surface/colored_mesh.h"
#include "fmv3d/surface/view_selection.h"

namespace fmv3d::surface {

struct AtlasOptions {
  int max_page_size = 4096;  // texels, side of a page (power of two, 256..16384)
  int margin = 2;            // texels kept around each chart
  double texel_scale = 1.0;  // atlas texels per source pixel (< 1 shrinks the atlas)
  bool adjust_colors = true;
  double gain_regularisation = 0.05;  // pull of each view's log-gain towards 0, relative to the seam terms
  void Check() const;
};

struct AtlasStats {
  size_t patches = 0;       // edge-connected faces on one view
  size_t charts = 0;        // view charts (a patch grown by the margin; overlapping ones merged)
  size_t unseen_faces = 0;  // faces no view textures (a flat block each)
  size_t seam_edges = 0;
  std::optional<double> max_gain_deviation;  // when the colours were adjusted
  int pages = 0;
  std::vector<std::pair<int, int>> page_size;  // width, height per page
  double atlas_fill = 0;                       // share of the pages' texels in a chart
  double seconds = 0;
};

struct TexturedModel {
  io::TexturedMesh mesh;                // faces grouped by page; materials "atlas_<page>" with their textures
  std::vector<io::Rgb8> vertex_colors;  // per mesh vertex, averaged from the texture (RGB)
  AtlasStats atlas;
  ViewSelectionStats selection;  // set by TextureMesh
  double seconds = 0;            // TextureMesh's whole run
};

// `frames` gives views[i]'s pixels: read in one pass over the labelled views (seam colours and chart copies).
TexturedModel BuildTextureAtlas(const ColoredMesh& mesh, const std::vector<Eigen::Vector3i>& adjacency,
                                const std::vector<TextureView>& views, FrameWindow& frames,
                                const std::vector<int>& labels, const AtlasOptions& options);

}  // namespace fmv3d::surface
