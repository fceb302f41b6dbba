// File helpers: every output is written to a temporary name in the same folder, flushed to the disk (fsync) and
// renamed when complete (then the folder is synced too), so neither a killed process nor a power cut leaves a
// truncated file that a later stage would take for finished output.
#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

namespace fmv3d::core {

namespace fs = std::filesystem;

// Calls write(tmp_path), fsyncs it, renames tmp_path to `path` and fsyncs the folder. The temporary is
// ".<stem>.tmp<pid><extension>" beside `path` (so writers that choose a format by extension still work). On
// exception the temporary is removed and it rethrows; a write, sync or rename failure (disk full, file size
// limit, permissions) throws fmv3d::Error naming `path` and the system's reason.
void WriteAtomically(const fs::path& path, const std::function<void(const fs::path& tmp)>& write);
void WriteTextFile(const fs::path& path, std::string_view text);  // bytes as they are (binary mode)
std::string ReadTextFile(const fs::path& path);
void WriteJson(const fs::path& path, const nlohmann::json& j);
nlohmann::json ReadJson(const fs::path& path);
// Creates the directory (and parents); throws fmv3d::Error naming it on failure.
void EnsureDirectory(const fs::path& dir);

}  // namespace fmv3d::core
