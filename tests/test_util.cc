#include "test_util.h"

#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

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
