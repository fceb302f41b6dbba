// Request validation for the console's HTTP API (docs/console-api.md), free of HTTP: workspace names, paths
// that must stay inside a root, token comparison, and the JSON bodies and query values the API accepts.
// Everything here is a pure function so that it can be unit-tested and fuzzed (tests/fuzz/http_request_fuzz.cc).
#pragma once

#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace fmv3d::server {

// A request the client got wrong: answered with `status` and {"error": message, "field": field}.
class RequestError : public std::runtime_error {
 public:
  RequestError(int status, const std::string& message, std::string field = {})
      : std::runtime_error(message), status_(status), field_(std::move(field)) {}
  int status() const { return status_; }
  const std::string& field() const { return field_; }

 private:
  int status_;
  std::string field_;
};

// The stages a job may start from / stop after, in `fmv3d reconstruct`'s order ("report" is written last).
const std::vector<std::string>& StageNames();
bool IsStageName(std::string_view name);

// One path component: [A-Za-z0-9._ -]+, at most 128 characters, not starting with '.'.
bool IsValidWorkspaceName(std::string_view name);

// Why ResolveInside refused a path; callers decide on it (403 for kLeavesRoot), the text is only for messages.
enum class PathRefusal { kNone, kEmpty, kNulByte, kBackslash, kAbsolute, kDotDot, kUnresolvable, kLeavesRoot };
const char* PathRefusalText(PathRefusal refusal);  // "empty path", …, "path leaves its root"

struct ResolvedPath {
  std::optional<std::filesystem::path> path;  // set when the path was accepted
  PathRefusal refusal = PathRefusal::kNone;   // why not, when path is unset
  explicit operator bool() const { return path.has_value(); }
  const std::filesystem::path& operator*() const { return *path; }
  const std::filesystem::path* operator->() const { return &*path; }
  const char* why() const { return PathRefusalText(refusal); }
};

// The file `relative` names inside `root` (which must be canonical), or a refusal when it is empty, contains a
// NUL byte or a backslash, is absolute, has a ".." component, cannot be resolved, or — after resolving every
// symlink of the part that exists — leaves `root`. The file itself need not exist.
ResolvedPath ResolveInside(const std::filesystem::path& root, std::string_view relative);

// True when `path` (canonical) is `root` (canonical) or below it, compared component by component.
bool IsWithin(const std::filesystem::path& root, const std::filesystem::path& path);

// Compares in time independent of where the strings differ (the token check).
bool ConstantTimeEquals(std::string_view a, std::string_view b);

// POST /api/workspaces/{ws}/jobs.
struct JobRequest {
  std::vector<std::string> inputs;  // as given; resolved against the workspace and WS_ROOT by the job runner
  std::string from, until;          // stage names or empty
  bool fast = false;
};
// Throws RequestError(400) naming the field: not a JSON object, "inputs" not an array of non-empty strings
// without NUL, "from"/"until" not a stage name (or until before from), "fast" not a boolean, unknown fields.
JobRequest ParseJobRequest(std::string_view body);

// POST /api/workspaces: {"name": NAME}; throws RequestError(400, ..., "name").
std::string ParseCreateWorkspace(std::string_view body);

struct LatLon {
  double lat = 0, lon = 0;
};
// "LAT,LON" in degrees (|lat| <= 90, |lon| <= 180); throws RequestError(400, ..., field).
LatLon ParseLatLon(std::string_view text, const std::string& field);
// A decimal integer in [lo, hi]; throws RequestError(400, ..., field).
int ParseBoundedInt(std::string_view text, int lo, int hi, const std::string& field);

// A file name for an upload: the last component of what the client sent, restricted to [A-Za-z0-9._ -] (other
// characters become '_'), never starting with '.', at most 128 characters; throws RequestError(400) when
// nothing usable is left.
std::string SanitiseUploadName(std::string_view client_name);

}  // namespace fmv3d::server
