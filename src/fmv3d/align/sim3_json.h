// Similarities as JSON — the `--transform` files of `fmv3d compare` and the similarities in align reports.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "fmv3d/core/pose.h"

namespace fmv3d::align {

// Similarity ↔ JSON {"scale": s, "rotation": [[r00, r01, r02], [..], [..]], "translation": [x, y, z]}
// (X' = s·R·X + t). Reading also takes {"scale", "q_wxyz", "t"} and a report holding such an object under
// "alignment" (report/sparse_eval.json of `fmv3d evaluate-sparse`: the model → truth similarity); it checks
// that R is a rotation (orthonormal, det +1 within 1e-6) and s > 0.
nlohmann::json Sim3ToJson(const core::Sim3& sim);
core::Sim3 Sim3FromJson(const nlohmann::json& j);  // throws fmv3d::Error saying what is wrong
core::Sim3 ReadSim3Json(const std::filesystem::path& path);

}  // namespace fmv3d::align
