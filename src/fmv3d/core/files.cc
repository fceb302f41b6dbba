#include "fmv3d/core/files.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
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
  const fs::path tmp =
      path.parent_path() / ("." + path.stem().string() + ".tmp" + std::to_string(getpid()) + path.extension().string());
  try {
    errno = 0;
    write(tmp);
    if (const int e = Sync(tmp, false)) throw Error(path.string() + ": cannot write (" + std::strerror(e) + ")");
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
    // The message names the file the user asked for, not its temporary.
    std::string what = e.what();
    for (size_t at; (at = what.find(tmp.string())) != std::string::npos;)
      what.replace(at, tmp.string().size(), path.string());
    if (err == ENOSPC || err == EFBIG || err == EDQUOT || err == EACCES || err == EROFS || err == EIO) {
      const std::string reason = std::strerror(err);
      if (what.find(reason) == std::string::npos) what += " (" + reason + ")";
    }
    throw Error(what);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

void WriteTextFile(const fs::path& path, std::string_view text) {
  WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
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

}  // namespace fmv3d::core
