// A stage that dies after writing its marker (a stage may write more files after it) must run again on resume
// when the runner keeps running flags; the workspace lock refuses a second holder and frees on release; the
// temporaries of a killed writer are recognised and removed.
#include <gtest/gtest.h>

#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/file_lock.h"
#include "fmv3d/pipeline/stage_runner.h"
#include "test_util.h"

namespace fmv3d::pipeline {
namespace {

namespace fs = std::filesystem;

TEST(InterruptedStage, MarkerWrittenThenDiedRunsAgainOnResume) {
  test::TempDir dir;
  std::ofstream(dir / "input") << "x";
  int runs = 0;
  bool die = true;
  const fs::path marker = dir / "marker";
  std::vector<Stage> stages{{"s", [&] { return std::vector<fs::path>{dir / "input"}; }, marker,
                             [&] {
                               ++runs;
                               std::ofstream(marker) << "done";
                               if (die) throw Error("died after the marker");  // as a kill would
                               return nlohmann::json::object();
                             }}};
  RunnerOptions options;
  options.state_dir = dir / ".stages";
  EXPECT_THROW(RunStages(stages, options), Error);
  EXPECT_TRUE(fs::exists(dir / ".stages" / "s.running"));
  die = false;
  const auto again = RunStages(stages, options);
  EXPECT_FALSE(again.at(0).skipped);
  EXPECT_EQ(runs, 2);
  EXPECT_FALSE(fs::exists(dir / ".stages" / "s.running"));
  EXPECT_TRUE(RunStages(stages, options).at(0).skipped);
  // Without running flags the same marker would have been trusted.
  die = true;
  EXPECT_THROW(RunStages({stages[0]}, RunnerOptions{"s", "", {}}), Error);
  EXPECT_TRUE(RunStages(stages, RunnerOptions{}).at(0).skipped);
}

TEST(WorkspaceLock, SecondHolderRefusedUntilTheFirstIsReleased) {
  test::TempDir dir;
  {
    const core::FileLock first(dir / ".lock", "WS");
    try {
      const core::FileLock second(dir / ".lock", "WS");
      FAIL() << "a second lock was granted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("WS: in use by another fmv3d process (pid "), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(core::FileLock(dir / ".lock", "WS"));
  EXPECT_THROW(core::FileLock(dir / "no such folder" / ".lock", "WS"), Error);
}

TEST(WorkspaceLock, StaleTemporariesRemoved) {
  test::TempDir dir;
  fs::create_directories(dir / "dense");
  for (const char* name : {"dense/.fused.tmp123.ply", ".hillshade.tmp9.png.png", "dense/fused.ply", "a.tmp1"})
    std::ofstream(dir / name) << "x";
  EXPECT_TRUE(core::IsAtomicTemporary("dense/.fused.tmp123.ply"));
  EXPECT_FALSE(core::IsAtomicTemporary("dense/fused.ply"));
  EXPECT_EQ(core::RemoveStaleTemporaries(dir.path()), 2u);
  EXPECT_TRUE(fs::exists(dir / "dense/fused.ply"));
  EXPECT_TRUE(fs::exists(dir / "a.tmp1"));
  EXPECT_FALSE(fs::exists(dir / "dense/.fused.tmp123.ply"));
}

}  // namespace
}  // namespace fmv3d::pipeline
