// The `fmv3d texture WS` stage: WS/mesh/poisson.ply + the registered images (WS/sparse COLMAP model,
// pixels from WS/frames/<name>) → per-face view selection (view_selection.h) → texture atlas
// (texture_atlas.h) →
//   WS/mesh/textured.obj + textured.mtl + textured_atlas_<i>.png   Wavefront OBJ with the atlas pages
//   WS/mesh/model.glb                                               binary glTF, textures embedded
//   WS/mesh/textured.ply                                            the mesh with colours from the texture
//   WS/report/texture.json                                          views, candidates, patches, pages, timings
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/surface/texture_atlas.h"
#include "fmv3d/surface/view_selection.h"

namespace fmv3d::surface {

struct TextureStageOptions {
  ViewSelectionOptions selection;
  AtlasOptions atlas;
  // > 0: colour from the fewest views that see every sparse point this many times (mvs::SelectReferenceViews)
  // instead of every registered view; the visibility pass costs per view, and video keyframes see each face
  // from 20-30 views, most of them near-duplicates. 0 = every view.
  int view_coverage = 0;
  // MB of decoded frames held at once (frame_window.h): the frames are read in two passes, and those that do
  // not fit are decoded again in the second. The output does not depend on it.
  double max_memory_mb = 2048;
  void Check() const {
    selection.Check();
    atlas.Check();
    if (view_coverage < 0) throw Error("texture: --view-coverage must be >= 0 (0 = every view)");
    if (!(max_memory_mb > 0)) throw Error("texture: --max-memory must be > 0 MB");
  }
};

// The registered images of `model`, without their pixels (LoadTextureFrame reads them). Throws fmv3d::Error
// naming a missing frame.
std::vector<TextureView> LoadTextureViews(const core::Reconstruction& model, const std::filesystem::path& frames_dir);
// The pixels of `view` from `frames_dir`. Throws fmv3d::Error naming an unreadable frame or one whose size
// differs from its camera's.
cv::Mat LoadTextureFrame(const TextureView& view, const std::filesystem::path& frames_dir);

// View selection + atlas for a mesh (the library entry without files): `frames` gives views[i]'s pixels.
TexturedModel TextureMesh(const ColoredMesh& mesh, const std::vector<TextureView>& views, FrameWindow& frames,
                          const TextureStageOptions& options);
// The same for views that hold their pixels.
TexturedModel TextureMesh(const ColoredMesh& mesh, const std::vector<TextureView>& views,
                          const TextureStageOptions& options);

// Returns the summary also written to WS/report/texture.json. Throws fmv3d::Error naming the missing input
// and the command that makes it.
nlohmann::json RunTextureStage(const core::Workspace& workspace, const TextureStageOptions& options);

}  // namespace fmv3d::surface
