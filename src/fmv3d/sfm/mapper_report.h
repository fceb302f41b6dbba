// The mapper's result as report/sparse.json holds it (the sparse stage's JSON edge): its counts and timings (the
// "mapper" object), each self-calibration decision, intrinsics posterior and focal decision, and every model.
#pragma once

#include <nlohmann/json.hpp>

#include "fmv3d/sfm/incremental_mapper.h"

namespace fmv3d::sfm {

nlohmann::json ToJson(const TrackSummary& t);
// {"run": false} when no pass ran, else one object per pass.
nlohmann::json ToJson(const std::vector<GuidedCompletionPass>& passes);
nlohmann::json ToJson(const MapperTimings& t);
nlohmann::json ToJson(const MapperStats& s);
// One self-calibration decision with the figures that made it (self_calibration.h).
nlohmann::json ToJson(const NestedModelTestResult& r);
// The final model's posterior of one camera's free intrinsics, and in words what the operator must know: which
// parameters the images leave uncertain at the pixel level, and by how much.
nlohmann::json ToJson(const IntrinsicsPosterior& p);
// null when no decision was recorded.
nlohmann::json ToJson(const FocalDecision& d);
// report/sparse.json without its timings: every model, the largest one's figures at the top, the left-out
// frames with their reasons, and the mapper's section (relocalisation's and tie points' are added by the stage).
nlohmann::json SparseReport(const MapperInput& input, const MapperResult& result);

}  // namespace fmv3d::sfm
