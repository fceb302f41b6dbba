// Mission-track alignment: independent reconstructions of one target — other flights, days,
// cameras — each in its own arbitrary frame and scale, brought into one frame without GPS.
//
// Coarse, per pair of tracks (reference ← moving):
//   1. cross-track image pairs: all of them for small tracks, else each image's most similar images of the
//      other track by a global bag-of-words descriptor (features/pairs.h);
//   2. SIFT matching of the keypoints that have a 3D point in their model (the others cannot give a 3D
//      correspondence), verified by an essential matrix on each model's own undistorted rays;
//   3. every verified match links a 3D point of one model to one of the other: RANSAC + Umeyama similarity
//      (geometry/similarity.h) on those 3D–3D pairs, then a robust (IRLS) least-squares refit on the inliers.
//   Too few consistent 3D pairs → "no overlap found between A and B".
// Fine: scaled point-to-plane ICP (icp.h) between the dense clouds (WS/dense/fused.ply) when both tracks
//   have one, trimmed to the overlap measured after the coarse step. Without dense clouds the refit on the
//   3D correspondences is the result (ICP between two sparse point sets — different points, no real
//   surfaces — is less precise than the correspondences themselves).
// Many tracks: every pair is tried; a maximum spanning tree over the pairs (weight: inlier count) rooted at
// the largest track (most registered images) gives each track's chain of similarities to the reference.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "fmv3d/align/icp.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/pose.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/features/matcher.h"
#include "fmv3d/io/point_cloud.h"

namespace fmv3d::align {

// The dense stage's settings a workspace was made with (WS/report/dense.json): a merged cloud is recomputed with the
// finest of every track's.
struct DenseSettings {
  int max_size = 0;  // 0: full resolution
  int max_sources = 0;
  bool geometric_pass = false;
  int reference_coverage = 0;
};

// One workspace's products.
struct Track {
  std::filesystem::path workspace;
  std::string name;                             // the workspace folder's name (for messages and reports)
  core::Reconstruction sparse;                  // WS/sparse (COLMAP text)
  io::OrientedPointCloud dense;                 // WS/dense/fused.ply, empty when absent
  std::optional<DenseSettings> dense_settings;  // none when the workspace has no dense report
  double radius = 0;                            // RMS distance of the sparse points to their centroid (model units)
};

// Throws fmv3d::Error when WS/sparse is missing or has fewer than 3 images or 3 points.
Track LoadTrack(const std::filesystem::path& workspace);

struct TrackAlignOptions {
  int exhaustive_max_pairs = 2500;  // all cross pairs when |A|·|B| is at most this, else by global descriptor
  int candidates_per_image = 5;     // most similar images of the other track, per image
  features::MatchOptions match;
  double verify_max_error_px = 2.0;  // essential-matrix inlier threshold, pixels
  int min_pair_inliers = 15;         // verified matches for an image pair to count
  int min_inliers = 20;              // consistent 3D–3D pairs for two tracks to overlap
  double ransac_max_error = 0.01;    // × the reference track's radius
  bool icp = true;                   // fine ICP on the dense clouds when both tracks have one
  IcpOptions icp_options;
  uint64_t seed = 42;
  void Check() const;  // throws fmv3d::Error naming the bad field
};

struct PairAlignment {
  size_t reference = 0, moving = 0;  // track indices; `sim` maps the moving track into the reference frame
  core::Sim3 sim;
  size_t image_pairs_tried = 0, image_pairs_verified = 0;
  size_t correspondences = 0;            // distinct 3D–3D pairs from verified matches
  size_t inliers = 0;                    // consistent with the similarity
  double overlap_fraction = 0;           // share of the moving track's points with a reference point nearby
  double rms_before = 0, rms_after = 0;  // fine step's residual RMS before / after (reference units)
  std::string fine;                      // "icp-dense" or "correspondences"
  // The consistent 3D–3D links (reference point id, moving point id), for the merge's joint bundle adjustment.
  std::vector<std::pair<uint64_t, uint64_t>> links;
  nlohmann::json ToJson(const std::vector<Track>& tracks) const;
};

// The tracks share too little to be aligned: "no overlap found between A and B" (a user-facing fmv3d::Error, and a
// type that AlignTracks tells apart from other failures).
class NoOverlapError : public Error {
 public:
  using Error::Error;
};

// Throws NoOverlapError when the tracks share too little.
PairAlignment AlignTrackPair(const std::vector<Track>& tracks, size_t reference, size_t moving,
                             const TrackAlignOptions& options);

struct MultiTrackAlignment {
  size_t reference = 0;                  // the largest track
  std::vector<core::Sim3> to_reference;  // per track: its frame → the reference frame
  std::vector<PairAlignment> tree;       // the spanning-tree edges used
  std::vector<PairAlignment> pairs;      // every pair that overlapped
};

// Throws fmv3d::Error for fewer than 2 tracks, or naming a track that overlaps no other (for two tracks:
// "no overlap found between A and B").
MultiTrackAlignment AlignTracks(const std::vector<Track>& tracks, const TrackAlignOptions& options);

}  // namespace fmv3d::align
