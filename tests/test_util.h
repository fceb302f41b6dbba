// Shared test helpers: temporary folders, the shared real-data folder (tests skip when it is absent), and
// running the fmv3d CLI as a user would.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <functional>
#include <string>

namespace fmv3d::test {

namespace fs = std::filesystem;

// A fresh empty folder under the system temp dir, removed when the object dies.
class TempDir {
 public:
  explicit TempDir(const std::string& tag = "fmv3d");
  ~TempDir();
  const fs::path& path() const { return path_; }
  fs::path operator/(const std::string& name) const { return path_ / name; }

 private:
  fs::path path_;
};

// A folder that `make` fills once for every process of this test binary: ctest runs each test in a process of
// its own, so a fixture held in a static was made again for every test (the surface tests' synthetic flight and
// mesh: most of their time, several minutes under the sanitizers). The first call makes it under the system
// temp dir (a folder per user); later calls, in this or another process of the same binary file, find it there. Keyed
// by `name`, the binary's path and its identity (inode, size, modification time): a rebuilt binary makes it again and
// removes its own older copies; processes asking at once wait for the one making it (a file lock). Read-only for the
// tests: copy what a test changes. Throws what `make` throws (nothing is left behind).
fs::path SharedFixture(const std::string& name, const std::function<void(const fs::path& dir)>& make);

// ../shared/data beside the checkout, or empty when absent.
fs::path SharedData();

struct CliResult {
  int exit_code = -1;
  std::string out, err;
};
// Runs the fmv3d binary built with the tests; args are passed through a shell (quote as needed).
CliResult RunCli(const std::string& args);

}  // namespace fmv3d::test

// Skips the current test when ../shared/data (or a path inside it) is missing.
#define FMV3D_REQUIRE_SHARED_DATA(rel)                                                                        \
  do {                                                                                                        \
    if (::fmv3d::test::SharedData().empty() || !std::filesystem::exists(::fmv3d::test::SharedData() / (rel))) \
      GTEST_SKIP() << "shared data not present: " << (rel);                                                   \
  } while (0)
