// File helpers: every output is written to a temporary name and renamed when complete, so an interrupted
// run never leaves a truncated file that a later stage would take for finished output.
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include <nlohmann/json.hpp>

namespace fmv3d::core {

namespace fs = std::filesystem;

// Calls write(tmp_path) and renames tmp_path to `path`. The temporary keeps `path`'s extension (so writers
// that choose a format by extension still work). On exception the temporary is removed and it rethrows.
void WriteAtomically(const fs::path& path, const std::function<void(const fs::path& tmp)>& write);
void WriteTextFile(const fs::path& path, const std::string& text);
std::string ReadTextFile(const fs::path& path);
void WriteJson(const fs::path& path, const nlohmann::json& j);
nlohmann::json ReadJson(const fs::path& path);
// Creates the directory (and parents); throws fmv3d::Error naming it on failure.
void EnsureDirectory(const fs::path& dir);

}  // namespace fmv3d::core
