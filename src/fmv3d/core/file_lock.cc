#include "fmv3d/core/file_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <regex>
#include <vector>

#include "fmv3d/core/error.h"

namespace fmv3d::core {

namespace fs = std::filesystem;

bool IsAtomicTemporary(const fs::path& path) {
  static const std::regex kTemp(R"(\..*\.tmp[0-9]+(\..*)?)");
  return std::regex_match(path.filename().string(), kTemp);
}

size_t RemoveStaleTemporaries(const fs::path& dir) {
  size_t removed = 0;
  std::error_code ec;
  std::vector<fs::path> stale;
  for (fs::recursive_directory_iterator it(dir, fs::directory_options::skip_permission_denied, ec), end;
       !ec && it != end; it.increment(ec))
    if (it->is_regular_file(ec) && IsAtomicTemporary(it->path())) stale.push_back(it->path());
  for (const auto& p : stale) removed += fs::remove(p, ec) ? 1 : 0;
  return removed;
}

FileLock::FileLock(const fs::path& lock_file, const std::string& what) {
  fd_ = open(lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0)
    throw Error(what + ": cannot create the lock file " + lock_file.string() + " (" + std::strerror(errno) + ")");
  if (flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char buf[32] = {};
    const ssize_t n = pread(fd_, buf, sizeof buf - 1, 0);
    close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK) {
      std::string pid = n > 0 ? std::string(buf, static_cast<size_t>(n)) : "";
      while (!pid.empty() && (pid.back() == '\n' || pid.back() == ' ')) pid.pop_back();
      throw Error(what + ": in use by another fmv3d process" + (pid.empty() ? "" : " (pid " + pid + ")") +
                  "; wait for it to finish or stop it, then run again");
    }
    throw Error(what + ": cannot lock " + lock_file.string() + " (" + std::strerror(err) + ")");
  }
  const std::string pid = std::to_string(getpid()) + "\n";
  if (ftruncate(fd_, 0) == 0 && pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
    // The pid is only for the message a second process prints; the lock holds without it.
  }
}

FileLock::~FileLock() {
  if (fd_ >= 0) close(fd_);  // closing the descriptor releases the flock
}

}  // namespace fmv3d::core
