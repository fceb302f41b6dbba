// The command line's contract: --help/--version succeed, unknown flags are usage errors (exit 2).
#include <gtest/gtest.h>

#include "test_util.h"

namespace fmv3d::test {
namespace {

TEST(Cli, HelpAndVersion) {
  auto r = RunCli("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("fmv3d"), std::string::npos);
  r = RunCli("--version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("fmv3d 0."), std::string::npos);
}

TEST(Cli, UnknownFlagIsAUsageError) {
  auto r = RunCli("--no-such-flag");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("no-such-flag"), std::string::npos);
  EXPECT_TRUE(r.out.empty());
  r = RunCli("");
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace fmv3d::test
