// libFuzzer target for our binary stage files: features/<frame>.feat, matches/matches.bin and dense/<view>.dmap.
// The same bytes go to all the readers (each checks its own magic first; seeds carry each magic). A file read
// must hold what its header says; anything else throws fmv3d::Error.
#include <cstddef>
#include <cstdint>

#include "fmv3d/core/error.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/mvs/depth_map.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fmv3d::fuzz::WriteScratch("in.bin", reinterpret_cast<const char*>(data), size);
  try {
    const auto f = fmv3d::features::ReadFeatures(path);
    if (static_cast<size_t>(f.descriptors.rows()) != f.keypoints.size() || f.colors.size() != f.keypoints.size())
      __builtin_trap();
  } catch (const fmv3d::Error&) {
  }
  try {
    const auto pairs = fmv3d::features::ReadMatches(path);
    std::vector<size_t> counts(4, 16);
    try {
      fmv3d::features::ValidateMatches(pairs, counts, "fuzz");
    } catch (const fmv3d::Error&) {
    }
  } catch (const fmv3d::Error&) {
  }
  // The pair-by-pair reader accepts exactly the files ReadMatches accepts, and reads the same pairs.
  std::vector<fmv3d::features::VerifiedPair> whole;
  bool whole_ok = true;
  try {
    whole = fmv3d::features::ReadMatches(path);
  } catch (const fmv3d::Error&) {
    whole_ok = false;
  }
  try {
    fmv3d::features::MatchFileReader reader(path);
    if (!whole_ok || reader.size() != whole.size()) __builtin_trap();
    for (size_t k = 0; k < reader.size(); ++k)
      if (reader.Read(k).inliers.size() != whole[k].inliers.size() || reader.ids(k).second != whole[k].image_id2)
        __builtin_trap();
  } catch (const fmv3d::Error&) {
    if (whole_ok) __builtin_trap();
  }
  try {
    const auto map = fmv3d::mvs::ReadDepthMap(path);
    (void)map.CountValid();
  } catch (const fmv3d::Error&) {
  }
  return 0;
}
