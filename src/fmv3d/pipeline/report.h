// WS/report/report.json + report.html: what a run produced, gathered from the stages' own summaries
// (frames.json, features/features.json, matches summary, report/sparse.json, report/dense.json,
// report/mesh.json, report/texture.json — whichever exist), timings, and pictures rendered with our own
// rasteriser: the sparse model with its cameras, the dense cloud, the textured (or Poisson) mesh.
#pragma once

#include <filesystem>

#include <nlohmann/json.hpp>

namespace fmv3d::pipeline {

// timings: stage name → seconds (or "skipped"); merged with report/timings.json of earlier runs so a resumed
// run still reports every stage's time. Returns report.json's content. Pictures that cannot be made (e.g. no
// dense cloud yet) are left out with a note, never an error.
nlohmann::json WriteReport(const std::filesystem::path& workspace, const nlohmann::json& timings);

}  // namespace fmv3d::pipeline
