// The operator's input to the match stage (WS/manual/tiepoints.json: tie points, single-frame keypoints, deleted
// automatic matches) applied to its verified pairs: only the pairs touching the frames the operator named are read
// back from automatic.bin and edited; matches.bin is then written pair by pair with those edits in place.
#pragma once

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <utility>
#include <vector>

#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/match_stage.h"
#include "fmv3d/features/pairs.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::features {

// The operator's changes to the verified pairs: the pairs touching the frames the operator named, as edited (absent
// when left with no match), and the pairs the tie points add.
struct OperatorEdits {
  bool used = false;
  std::set<uint32_t> frames;                                     // 0-based
  std::map<std::pair<uint32_t, uint32_t>, VerifiedPair> edited;  // by 1-based image ids
  std::vector<VerifiedPair> added;
  bool Touches(const std::pair<uint32_t, uint32_t>& ids) const {
    return frames.count(ids.first - 1) > 0 || frames.count(ids.second - 1) > 0;
  }
};

// The operator's tie points, keypoints and deleted matches, applied to the verified pairs (`verified`: their
// positions in `automatic`) and to `features`, which gain the clicked keypoints. Returns the summary for
// matches.json (its "pairs_added" is set once matches.bin is written). With no tie-point file, removes the last
// run's manual.json and returns {"used": false}.
nlohmann::json ApplyOperatorInput(const core::Workspace& ws, const io::FramesIndex& index, const DescriptorLoader& load,
                                  const MatchStageOptions& options, std::vector<FeatureSet>* features,
                                  MatchFileReader* automatic, const std::vector<size_t>& verified,
                                  OperatorEdits* edits);

// matches.bin: the verified pairs of `automatic` in pair order, pair by pair, with the operator's edits in their
// place (a pair left with no match dropped) and the pairs the operator added last. Returns the pair count.
size_t WriteFinalMatches(MatchFileReader* automatic, const std::vector<size_t>& verified, const OperatorEdits& edits,
                         const std::filesystem::path& path);

}  // namespace fmv3d::features
