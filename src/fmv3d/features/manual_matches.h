// The operator's tie points, single-frame keypoints and deleted matches (io/tiepoints.h) turned into feature
// correspondences (docs/manual-inputs.md):
//   - every clicked point becomes a keypoint appended to its frame's automatic ones (index = automatic count +
//     rank), with an upright SIFT descriptor computed there and the image's colour;
//   - a tie point adds a correspondence to every pair of frames it links, which verification never discards
//     (pairs that automatic matching rejected are created with the tie points alone); one that lies farther
//     than max_epipolar_px from the epipolar line of the pair's automatic F is reported, and kept — for pairs
//     whose F is determined (not planar-or-rotation, ≥ min_check_inliers F inliers);
//   - a single-frame keypoint is searched in every frame that verified a pair with its frame: the keypoints of
//     that frame within max_epipolar_px of its epipolar line, nearest by descriptor under Lowe's ratio; the
//     matches found make a track like a tie point's;
//   - deleted matches leave their pair's inliers.
// The layout of the appended keypoints is matches/manual.json (written by `match`, read by `sparse`, which
// appends the same keypoints in the same order).
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "fmv3d/features/types.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/tiepoints.h"

namespace fmv3d::features {

struct ManualMatchOptions {
  double max_epipolar_px = 4;    // tie points farther than this from the automatic epipolar line are reported
  int min_check_inliers = 30;    // ... of pairs with at least this many F inliers, not planar (F determined)
  double keypoint_scale_px = 4;  // the descriptor's scale at a clicked point
  double keypoint_ratio = 0.8;   // single-frame keypoints: Lowe's ratio among the candidates on the line
  void Check() const;
};

enum class ManualTrackKind : uint8_t { kTiePoint, kKeypoint };

struct ManualObservation {
  uint32_t image = 0;     // 0-based index into frames.json's frames
  uint32_t keypoint = 0;  // index into that frame's (extended) keypoints
};

struct ManualTrack {
  std::string id;
  ManualTrackKind kind = ManualTrackKind::kTiePoint;
  std::vector<ManualObservation> observations;
};

struct EpipolarDisagreement {
  std::string id;
  uint32_t image1 = 0, image2 = 0;  // 0-based
  double epipolar_px = 0;           // symmetric: the larger of the two point-to-line distances
};

// The appended keypoints per image (0-based index) and their tracks.
struct ManualMatches {
  struct Appended {
    uint32_t first_index = 0;      // the image's automatic keypoint count
    std::vector<std::string> ids;  // the tie point / keypoint each appended keypoint belongs to
    std::vector<Keypoint> keypoints;
    Descriptors descriptors;
    std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;
  };
  std::map<uint32_t, Appended> appended;
  std::vector<ManualTrack> tracks;
  std::vector<EpipolarDisagreement> disagreeing;
  size_t deleted = 0, deleted_not_found = 0, keypoints_matched = 0;
  bool empty() const { return appended.empty() && deleted == 0; }

  nlohmann::json ToJson(const io::FramesIndex& index) const;
  // Reads what ToJson wrote; frame names are looked up in `index`. Throws fmv3d::Error naming what is wrong.
  static ManualMatches FromJson(const nlohmann::json& j, const io::FramesIndex& index);
};

// Appends the keypoints, descriptors and colours of `appended` to a feature set holding exactly the automatic
// keypoints (appended.first_index of them); throws fmv3d::Error naming `what` when it holds another count.
void AppendToFeatureSet(const ManualMatches::Appended& appended, FeatureSet* features, const std::string& what);

// Appends the clicked points to `features` (one FeatureSet per frame of `index`, in its order) and returns their
// layout; `images[i]` is frame i's image (8-bit, as cv::imread gives; empty: descriptors zero, colour black) —
// only frames with clicked points are read. Tie points and keypoints naming frames that are not in `index` are an
// fmv3d::Error (check the file first: io::CheckTiePoints).
ManualMatches AppendManualKeypoints(const io::TiePoints& tie_points, const io::FramesIndex& index,
                                    const std::map<uint32_t, cv::Mat>& images, std::vector<FeatureSet>* features,
                                    const ManualMatchOptions& options);

// Adds the tracks' correspondences to `pairs` (verified pairs, image ids 1-based), matches single-frame keypoints,
// removes deleted matches and fills manual->disagreeing. `features` are the extended sets.
void ApplyManualMatches(const io::TiePoints& tie_points, const io::FramesIndex& index,
                        const std::vector<FeatureSet>& features, const ManualMatchOptions& options,
                        ManualMatches* manual, std::vector<VerifiedPair>* pairs);

// matches/manual.json
std::filesystem::path ManualMatchesPath(const std::filesystem::path& matches_dir);

}  // namespace fmv3d::features
