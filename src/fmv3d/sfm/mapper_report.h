// The mapper's counts and timings as report/sparse.json's "mapper" object (the sparse stage's edge).
#pragma once

#include <nlohmann/json.hpp>

#include "fmv3d/sfm/incremental_mapper.h"

namespace fmv3d::sfm {

nlohmann::json ToJson(const TrackSummary& t);
// {"run": false} when no pass ran, else one object per pass.
nlohmann::json ToJson(const std::vector<GuidedCompletionPass>& passes);
nlohmann::json ToJson(const MapperTimings& t);
nlohmann::json ToJson(const MapperStats& s);

}  // namespace fmv3d::sfm
