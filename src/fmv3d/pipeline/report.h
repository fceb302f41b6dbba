// WS/report/report.json + report.html: what a run produced, gathered from the stages' own summaries
// (frames.json, features/features.json, matches summary, report/sparse.json, report/dense.json,
// report/mesh.json, report/texture.json — whichever exist), timings, and pictures rendered with our own
// rasteriser: the sparse model with its cameras, the dense cloud, the textured (or Poisson) mesh.
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

namespace fmv3d::pipeline {

// Merges this run's stage timings (stage name → seconds, or "skipped") into WS/report/timings.json, so a
// resumed run still reports the time of every stage that ran in an earlier run.
void RecordTimings(const std::filesystem::path& workspace, const nlohmann::json& timings);

// Writes report.json + report.html from whatever the workspace holds (timings from report/timings.json).
// Returns report.json's content. Pictures that cannot be made (e.g. no dense cloud yet) are left out with a
// note, never an error.
nlohmann::json WriteReport(const std::filesystem::path& workspace);

}  // namespace fmv3d::pipeline
