// Machine-readable progress for a supervising process: when a progress log is open (`fmv3d reconstruct
// --progress-json FILE`), every core::Progress update and every stage start/end is appended to FILE as one JSON
// object per line, flushed at once, so that a reader tailing the file (the console's job runner) sees the run as
// it happens. Events (each also carries "t": Unix seconds):
//   {"event": "stages", "stages": ["frames", ...]}                         the run's stage list, first
//   {"event": "stage", "stage": NAME, "state": "start|done|skipped|failed", "index": i, "count": n, "seconds"}
//   {"event": "progress", "label": LABEL, "done": d, "total": n, "eta_s": s}   at most every 0.5 s, and at the end
#pragma once

#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace fmv3d::core {

// Opens (appending, created if absent) the progress log; throws fmv3d::Error naming the file when it cannot.
void OpenProgressLog(const std::filesystem::path& path);
void CloseProgressLog();
bool ProgressLogOpen();
// Appends one event line (thread-safe); a no-op when no log is open.
void AppendProgressEvent(nlohmann::json event);
// A "progress" event for core::Progress `label`, written at most every 0.5 s per label, and always when `final`.
void AppendProgressUpdate(const std::string& label, size_t done, size_t total, double eta_s, bool final);

}  // namespace fmv3d::core
