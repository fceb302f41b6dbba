// The automatic matching results of the last `match` run, kept for the next one (WS/matches/automatic.bin and
// automatic.json): re-running from matching (after the operator adds tie points, or after frames were added or
// re-extracted) matches and verifies only the pairs whose inputs changed.
//
// A pair's automatic result is a function of the two frames' feature files (their bytes), their prior cameras
// (and whether the prior is trusted), their 0-based indices (the kd-forest and RANSAC seeds) and the matching and
// verification options: a pair is read back when all of these are as recorded, else matched again. Tie points,
// keypoints and deleted matches are applied after this, on every run (manual_matches.h), and never cached.
// kAutomaticMatchesVersion is raised whenever matching or verification would give another result for the same
// inputs; `fmv3d match --force` recomputes every pair.
//
// automatic.json: {"format": "fmv3d-automatic-matches", "version", "options": key, "frames": [key per frame],
//                  "pairs": [[i, j, verified 0/1], ...]}; automatic.bin: every tried pair in that order
//                  (feature_io.h's match format; a rejected pair keeps its counts and no inliers).
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "fmv3d/features/matcher.h"
#include "fmv3d/features/pairs.h"
#include "fmv3d/features/types.h"
#include "fmv3d/geometry/two_view.h"

namespace fmv3d::features {

inline constexpr int kAutomaticMatchesVersion = 1;

struct AutomaticMatches {
  std::string options_key;
  std::vector<std::string> frame_keys;  // per frame, in frames.json order
  struct Result {
    VerifiedPair pair;
    bool verified = false;
  };
  std::map<ImagePair, Result> pairs;

  // The recorded result of pair (i, j) when the current keys match the recorded ones, else nullptr.
  const Result* Find(const ImagePair& p, const std::string& options, const std::vector<std::string>& frames) const;
};

// What a pair's automatic result depends on besides the two frames: the options and the program's version.
std::string OptionsKey(const MatchOptions& match, const geometry::TwoViewOptions& verify);

// A frame's key: its feature file's size and 64-bit FNV-1a hash, and `camera` (its prior, serialised).
std::string FrameKey(const std::filesystem::path& feature_file, const std::string& camera);

// Empty (no pairs) when the files are missing, of another version or unreadable: nothing is reused then.
AutomaticMatches ReadAutomaticMatches(const std::filesystem::path& matches_dir);
// Every tried pair's result (`results[k]` of `pairs[k]`, `verified[k]`), with the keys it was computed under.
void WriteAutomaticMatches(const std::filesystem::path& matches_dir, const std::string& options_key,
                           const std::vector<std::string>& frame_keys, const std::vector<ImagePair>& pairs,
                           const std::vector<VerifiedPair>& results, const std::vector<char>& verified);

}  // namespace fmv3d::features
