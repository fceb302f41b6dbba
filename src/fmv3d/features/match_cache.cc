#include "fmv3d/features/match_cache.h"

#include <spdlog/spdlog.h>

#include <cstdio>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"

namespace fmv3d::features {
namespace fs = std::filesystem;

namespace {

fs::path AutomaticJsonPath(const fs::path& dir) { return dir / "automatic.json"; }

}  // namespace

fs::path AutomaticBinPath(const fs::path& dir) { return dir / "automatic.bin"; }

const AutomaticMatches::Entry* AutomaticMatches::Find(const ImagePair& p, const std::string& options,
                                                      const std::vector<std::string>& frames) const {
  if (options != options_key || p.second >= frames.size() || p.second >= frame_keys.size()) return nullptr;
  if (frame_keys[p.first] != frames[p.first] || frame_keys[p.second] != frames[p.second]) return nullptr;
  const auto it = pairs.find(p);
  return it == pairs.end() ? nullptr : &it->second;
}

std::string OptionsKey(const MatchOptions& m, const geometry::TwoViewOptions& v) {
  return nlohmann::json{FMV3D_VERSION,
                        m.ratio,
                        m.mutual,
                        static_cast<int>(m.type),
                        m.flann_trees,
                        m.flann_checks,
                        m.brute_force_max_product,
                        m.seed,
                        v.max_error_px,
                        v.confidence,
                        v.max_iterations,
                        v.min_inliers,
                        v.min_E_F_inlier_ratio,
                        v.max_H_inlier_ratio,
                        v.refine,
                        v.seed}
      .dump();
}

std::string FrameKey(const fs::path& feature_file, const std::string& camera) {
  std::ifstream in(feature_file, std::ios::binary);
  if (!in) throw Error(feature_file.string() + ": cannot read");
  uint64_t h = 14695981039346656037ull, size = 0;
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const std::streamsize got = in.gcount();
    for (std::streamsize k = 0; k < got; ++k) h = (h ^ static_cast<unsigned char>(buf[k])) * 1099511628211ull;
    size += static_cast<uint64_t>(got);
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return std::to_string(size) + ":" + hex + ":" + camera;
}

AutomaticMatches ReadAutomaticMatches(const fs::path& dir) {
  AutomaticMatches m;
  if (!fs::exists(AutomaticJsonPath(dir)) || !fs::exists(AutomaticBinPath(dir))) return m;
  try {
    const auto j = core::ReadJson(AutomaticJsonPath(dir));
    if (j.at("format").get<std::string>() != "fmv3d-automatic-matches" ||
        j.at("version").get<int>() != kAutomaticMatchesVersion)
      return m;
    m.bin = std::make_unique<MatchFileReader>(AutomaticBinPath(dir));
    const auto& rows = j.at("pairs");
    if (rows.size() != m.bin->size()) throw Error("automatic.json and automatic.bin disagree on the pair count");
    m.options_key = j.at("options").get<std::string>();
    m.frame_keys = j.at("frames").get<std::vector<std::string>>();
    for (size_t k = 0; k < rows.size(); ++k) {
      const ImagePair p{rows[k].at(0).get<uint32_t>(), rows[k].at(1).get<uint32_t>()};
      if (m.bin->ids(k) != std::make_pair(p.first + 1, p.second + 1))
        throw Error("automatic.json and automatic.bin disagree on pair " + std::to_string(k));
      m.pairs[p] = {k, rows[k].at(2).get<int>() != 0};
    }
  } catch (const std::exception& e) {
    spdlog::warn("match: {} not used ({}): every pair is matched again", AutomaticJsonPath(dir).string(), e.what());
    return AutomaticMatches{};
  }
  return m;
}

AutomaticMatchesWriter::AutomaticMatchesWriter(fs::path dir, std::string options_key,
                                               std::vector<std::string> frame_keys)
    : dir_(std::move(dir)),
      options_key_(std::move(options_key)),
      frame_keys_(std::move(frame_keys)),
      bin_((core::EnsureDirectory(dir_), AutomaticBinPath(dir_))) {}

void AutomaticMatchesWriter::Add(const ImagePair& pair, const VerifiedPair& result, bool verified) {
  rows_.push_back({pair.first, pair.second, verified ? 1 : 0});
  bin_.Add(result);
}

void AutomaticMatchesWriter::Finish() {
  // The json names the bin's pairs: removed first, written last, so a run killed in between leaves no stale pair.
  fs::remove(AutomaticJsonPath(dir_));
  bin_.Finish();
  core::WriteJson(AutomaticJsonPath(dir_), {{"format", "fmv3d-automatic-matches"},
                                            {"version", kAutomaticMatchesVersion},
                                            {"options", options_key_},
                                            {"frames", frame_keys_},
                                            {"pairs", std::move(rows_)}});
}

}  // namespace fmv3d::features
