// Binary files of the features and match stages (DESIGN.md: our own binary files carry a magic, a version and
// sizes, and are checked on read). Both formats are little-endian, fixed-width, no padding.
//
// features/<frame-stem>.feat
//   char[8] "FMV3DFEA", uint32 version (1), int32 width, int32 height, uint32 num_keypoints N,
//   uint32 name_length L, char[L] image_name,
//   N x {float x, y, scale, orientation}          (pixels, fmv3d convention: pixel centres at +0.5)
//   N x 128 uint8 descriptors (row-major),  N x 3 uint8 RGB,  char[8] "FEA-END."
//
// matches/matches.bin
//   char[8] "FMV3DMAT", uint32 version (1), uint32 num_pairs P, then P x {
//     uint32 image_id1, image_id2, uint8 geometry, uint8 has_pose, uint32 num_putative, num_inliers_F,
//     num_inliers_E, num_inliers_H, float64 F[9], E[9], H[9], R[9] (row-major), t[3],
//     float64 median_triangulation_angle_deg, uint32 num_inliers M, M x {uint32 idx1, idx2} }
//   char[8] "MAT-END."
//
// Readers throw fmv3d::Error("<file>: <what is wrong>") on a missing, truncated, foreign or inconsistent file
// (wrong magic, unknown version, counts that do not fit the file size, keypoint indices out of range are the
// reader's caller's business — see ValidateMatches).
#pragma once

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "fmv3d/features/types.h"

namespace fmv3d::features {

inline constexpr uint32_t kFeatureFileVersion = 2;  // 2 adds the contrast threshold; 1 is still read
inline constexpr uint32_t kMatchFileVersion = 1;

// Written atomically (temporary + rename).
void WriteFeatures(const FeatureSet& features, const std::filesystem::path& path);
// With `descriptors` false the descriptor block is checked but not kept (descriptors has 0 rows): what a stage
// that holds every image's keypoints needs, at a ninth of the memory (16 + 3 bytes per keypoint instead of 147).
FeatureSet ReadFeatures(const std::filesystem::path& path, bool descriptors = true);

void WriteMatches(const std::vector<VerifiedPair>& pairs, const std::filesystem::path& path);
std::vector<VerifiedPair> ReadMatches(const std::filesystem::path& path);

// A match file written pair by pair, as WriteMatches writes it, holding none of them: into a temporary beside
// `path` that Finish moves there atomically (a writer destroyed unfinished leaves `path` as it was).
class MatchFileWriter {
 public:
  explicit MatchFileWriter(std::filesystem::path path);
  ~MatchFileWriter();
  MatchFileWriter(const MatchFileWriter&) = delete;
  MatchFileWriter& operator=(const MatchFileWriter&) = delete;
  void Add(const VerifiedPair& pair);
  void Finish();
  size_t count() const { return count_; }

 private:
  void Flush(const std::vector<char>& bytes);
  std::filesystem::path path_, part_;
  std::ofstream out_;
  size_t count_ = 0;
  bool finished_ = false;
};

// A match file read pair by pair: the constructor checks the whole file as ReadMatches does (throwing the same
// errors) and notes where each pair starts, so that only the pair read is held (12 bytes per pair besides).
class MatchFileReader {
 public:
  explicit MatchFileReader(const std::filesystem::path& path);
  ~MatchFileReader();
  size_t size() const { return offsets_.size(); }
  // Pair k's 1-based image ids, without reading it.
  std::pair<uint32_t, uint32_t> ids(size_t k) const { return ids_.at(k); }
  VerifiedPair Read(size_t k);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::vector<uint64_t> offsets_;
  std::vector<std::pair<uint32_t, uint32_t>> ids_;
};

// features/<frame-stem>.feat for a frame named e.g. "clip-000012.png".
std::filesystem::path FeaturePath(const std::filesystem::path& features_dir, const std::string& frame_name);
// matches/matches.bin and matches/matches.json.
std::filesystem::path MatchesPath(const std::filesystem::path& matches_dir);
std::filesystem::path MatchesSummaryPath(const std::filesystem::path& matches_dir);

// Throws fmv3d::Error when a pair refers to an image id outside [1, num_keypoints.size()] or a keypoint index
// outside that image's keypoints (num_keypoints[id - 1]); `what` names the file in the message.
void ValidateMatches(const std::vector<VerifiedPair>& pairs, const std::vector<size_t>& num_keypoints,
                     const std::string& what);

}  // namespace fmv3d::features
