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
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/matcher.h"
#include "fmv3d/features/pairs.h"
#include "fmv3d/features/types.h"
#include "fmv3d/geometry/two_view.h"

namespace fmv3d::features {

inline constexpr int kAutomaticMatchesVersion = 1;

// The last run's results, read pair by pair from automatic.bin: only where each pair lies is held.
struct AutomaticMatches {
  std::string options_key;
  std::vector<std::string> frame_keys;  // per frame, in frames.json order
  struct Entry {
    size_t index = 0;  // in automatic.bin
    bool verified = false;
  };
  std::map<ImagePair, Entry> pairs;
  std::unique_ptr<MatchFileReader> bin;

  // The recorded entry of pair (i, j) when the current keys match the recorded ones, else nullptr.
  const Entry* Find(const ImagePair& p, const std::string& options, const std::vector<std::string>& frames) const;
  // The pair's result (one thread at a time).
  VerifiedPair Read(const Entry& e) const { return bin->Read(e.index); }
};

// What a pair's automatic result depends on besides the two frames: the options and the program's version.
std::string OptionsKey(const MatchOptions& match, const geometry::TwoViewOptions& verify);

// A frame's key: its feature file's size and 64-bit FNV-1a hash, and `camera` (its prior, serialised).
std::string FrameKey(const std::filesystem::path& feature_file, const std::string& camera);

std::filesystem::path AutomaticBinPath(const std::filesystem::path& matches_dir);

// Empty (no pairs) when the files are missing, of another version or unreadable: nothing is reused then.
AutomaticMatches ReadAutomaticMatches(const std::filesystem::path& matches_dir);

// Every tried pair's result, added in pair order as it comes, with the keys it was computed under; the files are
// replaced by Finish (the previous ones stay readable until then).
class AutomaticMatchesWriter {
 public:
  AutomaticMatchesWriter(std::filesystem::path matches_dir, std::string options_key,
                         std::vector<std::string> frame_keys);
  void Add(const ImagePair& pair, const VerifiedPair& result, bool verified);
  void Finish();

 private:
  std::filesystem::path dir_;
  std::string options_key_;
  std::vector<std::string> frame_keys_;
  MatchFileWriter bin_;
  nlohmann::json rows_ = nlohmann::json::array();
};

}  // namespace fmv3d::features
