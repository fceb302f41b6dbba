// Guarding a workspace against a second writer and against what a killed writer left: an flock-based lock and
// the removal of core::WriteAtomically's unfinished temporaries.
#pragma once

#include <filesystem>
#include <string>

namespace fmv3d::core {

// True for a name core::WriteAtomically uses for its temporaries (".<stem>.tmp<pid><extension>").
bool IsAtomicTemporary(const std::filesystem::path& path);
// Removes the temporaries a killed process left under `dir` (recursively); call it only while holding the
// folder's lock (no other writer is alive). Returns how many were removed.
size_t RemoveStaleTemporaries(const std::filesystem::path& dir);

// An exclusive advisory lock (flock) on a file, held while the object lives. The kernel releases it when the
// process ends in any way (SIGKILL included), so a killed run never leaves it stuck. The file keeps the holder's
// pid, for the message a second process gets.
class FileLock {
 public:
  // Throws fmv3d::Error "<what>: in use by another fmv3d process (pid N) ..." when another process holds it, or
  // naming the file and the reason when it cannot be created.
  FileLock(const std::filesystem::path& lock_file, const std::string& what);
  ~FileLock();
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace fmv3d::core
