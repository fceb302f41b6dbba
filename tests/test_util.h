// Shared test helpers: temporary folders, the shared real-data folder (tests skip when it is absent), and
// running the fmv3d CLI as a user would.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
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
