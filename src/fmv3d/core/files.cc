#include "fmv3d/core/files.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::core {

namespace {

// fsync of a file or folder; returns errno (0 on success).
int Sync(const fs::path& p, bool directory) {
  const int fd = open(p.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) return errno;
  const int rc = fsync(fd) == 0 ? 0 : errno;
  close(fd);
  return rc;
}

}  // namespace

void WriteAtomically(const fs::path& path, const std::function<void(const fs::path& tmp)>& write) {
  if (path.has_parent_path()) EnsureDirectory(path.parent_path());
  const fs::path tmp = path.parent_path() / ("." + path.stem().string() + ".tmp" + std::to_string(getpid()) +
                                             path.extension().string());
  try {
    errno = 0;
    write(tmp);
    if (const int e = Sync(tmp, false))
      throw Error(path.string() + ": cannot write (" + std::strerror(e) + ")");
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw Error(path.string() + ": cannot write (" + ec.message() + ")");
    // The rename itself is durable once the folder is synced; a failure here loses nothing already renamed.
    Sync(path.has_parent_path() ? path.parent_path() : fs::path("."), true);
  } catch (const Error& e) {
    // A writer's generic "write failed" gains the system's reason (ENOSPC, EFBIG, EACCES) when there is one.
    const int err = errno;
    std::error_code ec;
    fs::remove(tmp, ec);
    if (err == ENOSPC || err == EFBIG || err == EDQUOT || err == EACCES || err == EROFS || err == EIO) {
      const std::string reason = std::strerror(err);
      if (std::string(e.what()).find(reason) == std::string::npos) throw Error(std::string(e.what()) + " (" + reason + ")");
    }
    throw;
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

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

void WriteTextFile(const fs::path& path, const std::string& text) {
  WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw Error(path.string() + ": write failed");
  });
}

std::string ReadTextFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteJson(const fs::path& path, const nlohmann::json& j) { WriteTextFile(path, j.dump(2) + "\n"); }

nlohmann::json ReadJson(const fs::path& path) {
  const std::string text = ReadTextFile(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path.string() + ": not valid JSON (" + e.what() + ")");
  }
}

void EnsureDirectory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error(dir.string() + ": cannot create directory (" + ec.message() + ")");
}

FileLock::FileLock(const fs::path& lock_file, const std::string& what) {
  fd_ = open(lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw Error(what + ": cannot create the lock file " + lock_file.string() + " (" + std::strerror(errno) + ")");
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
