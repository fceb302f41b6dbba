// test::SharedFixture (tests/test_util.h): a fixture folder made once for every process of a test binary.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <stdexcept>
#include <string>

#include "test_util.h"

namespace fmv3d::test {
namespace {

std::string Slurp(const fs::path& p) {
  std::ifstream in(p);
  std::string s;
  std::getline(in, s);
  return s;
}

TEST(SharedFixture, MadeOnceThenFoundAndAFailedMakeLeavesNothing) {
  const std::string name = "shared-fixture-test-" + std::to_string(getpid());  // fresh for this process
  int made = 0;
  auto make = [&](const fs::path& dir) {
    ++made;
    std::ofstream(dir / "value.txt") << "made " << made << "\n";
  };
  const fs::path first = SharedFixture(name, make);
  const fs::path again = SharedFixture(name, make);
  EXPECT_EQ(first, again);
  EXPECT_EQ(made, 1);
  EXPECT_EQ(Slurp(first / "value.txt"), "made 1");

  const std::string broken = name + "-broken";
  EXPECT_THROW(SharedFixture(broken,
                             [](const fs::path& dir) {
                               std::ofstream(dir / "half.txt") << "half";
                               throw std::runtime_error("render failed");
                             }),
               std::runtime_error);
  // Nothing of the failed attempt is left, so the next call makes it afresh.
  for (const auto& entry : fs::directory_iterator(first.parent_path()))
    if (entry.is_directory())
      EXPECT_EQ(entry.path().filename().string().find(broken + "@"), std::string::npos) << entry.path();
  int remade = 0;
  const fs::path fixed = SharedFixture(broken, [&](const fs::path&) { ++remade; });
  EXPECT_EQ(remade, 1);
  EXPECT_TRUE(fs::is_directory(fixed));
  for (const auto& entry : fs::directory_iterator(first.parent_path()))  // this test's folders and lock files
    if (entry.path().filename().string().find(name) != std::string::npos) fs::remove_all(entry.path());
}

}  // namespace
}  // namespace fmv3d::test
