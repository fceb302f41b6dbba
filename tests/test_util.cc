#include "test_util.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

namespace fmv3d::test {

TempDir::TempDir(const std::string& tag) {
  std::random_device rd;
  path_ = fs::temp_directory_path() / (tag + "-" + std::to_string(getpid()) + "-" + std::to_string(rd()));
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  if (!std::getenv("FMV3D_KEEP_TEST_DIRS")) fs::remove_all(path_, ec);
}

namespace {

// An exclusive flock on a file, held for the object's life.
class FileLock {
 public:
  explicit FileLock(const fs::path& path) : fd_(open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)) {
    if (fd_ < 0 || flock(fd_, LOCK_EX) != 0) throw std::runtime_error("cannot lock " + path.string());
  }
  ~FileLock() {
    flock(fd_, LOCK_UN);
    close(fd_);
  }
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_;
};

}  // namespace

fs::path SharedFixture(const std::string& name, const std::function<void(const fs::path& dir)>& make) {
  const fs::path exe = fs::read_symlink("/proc/self/exe");
  struct stat st {};
  if (stat(exe.c_str(), &st) != 0) throw std::runtime_error("cannot stat " + exe.string());
  // Copies of this fixture for this binary path share the prefix; the suffix names one build of it.
  const std::string prefix =
      exe.filename().string() + "-" + std::to_string(std::hash<std::string>{}(exe.string())) + "-" + name + "@";
  const std::string build = std::to_string(st.st_ino) + "-" + std::to_string(st.st_size) + "-" +
                            std::to_string(st.st_mtim.tv_sec) + "." + std::to_string(st.st_mtim.tv_nsec);
  // Per user: another user's folder under a shared /tmp would not be writable.
  const fs::path root = fs::temp_directory_path() / ("fmv3d-test-fixtures-" + std::to_string(getuid()));
  fs::create_directories(root);
  fs::path dir = root / (prefix + build);
  const FileLock lock(root / (prefix + "lock"));
  if (fs::is_directory(dir)) return dir;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(root)) {
    const std::string file = entry.path().filename().string();
    if (file.rfind(prefix, 0) == 0 && entry.is_directory()) fs::remove_all(entry.path(), ec);
  }
  const fs::path tmp = root / (prefix + "making-" + std::to_string(getpid()));
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp);
  try {
    make(tmp);
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  fs::rename(tmp, dir);
  return dir;
}

fs::path SharedData() {
  const fs::path p = FMV3D_SHARED_DATA;
  return fs::is_directory(p) ? p : fs::path();
}

static std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

CliResult RunCli(const std::string& args) {
  TempDir tmp("fmv3d-cli");
  const std::string cmd = std::string("'") + FMV3D_CLI + "' " + args + " >'" + (tmp / "out").string() + "' 2>'" +
                          (tmp / "err").string() + "'";
  const int status = std::system(cmd.c_str());
  CliResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = Slurp(tmp / "out");
  r.err = Slurp(tmp / "err");
  return r;
}

}  // namespace fmv3d::test
