#include "fmv3d/pipeline/stage_runner.h"

#include <gtest/gtest.h>

#include <fstream>
#include <thread>

#include "fmv3d/core/error.h"
#include "fmv3d/pipeline/reconstruct.h"
#include "test_util.h"

namespace fmv3d::pipeline {
namespace {

namespace fs = std::filesystem;

// Three stages a → b → c, each writing its marker; counts how often each ran.
struct Chain {
  explicit Chain(const fs::path& dir) : dir(dir) {
    std::ofstream(dir / "input") << "x";
    for (int i = 0; i < 3; ++i) {
      const fs::path in = i == 0 ? dir / "input" : dir / ("m" + std::to_string(i - 1));
      const fs::path marker = dir / ("m" + std::to_string(i));
      stages.push_back({std::string(1, char('a' + i)), [in] { return std::vector<fs::path>{in}; }, marker,
                        [this, i, marker] {
                          if (fail_at == i) throw Error("stage failed on purpose");
                          ++runs[i];
                          std::ofstream(marker) << "done";
                          return nlohmann::json{{"stage", i}};
                        }});
    }
  }
  fs::path dir;
  std::vector<Stage> stages;
  int runs[3] = {0, 0, 0};
  int fail_at = -1;
};

TEST(StageRunner, ResumesAfterAFailureAndSkipsFinishedStages) {
  test::TempDir dir;
  Chain chain(dir.path());
  chain.fail_at = 1;
  EXPECT_THROW(RunStages(chain.stages, {}), Error);
  EXPECT_EQ(chain.runs[0], 1);
  EXPECT_EQ(chain.runs[1], 0);
  chain.fail_at = -1;
  const auto results = RunStages(chain.stages, {});
  EXPECT_EQ(chain.runs[0], 1);  // finished before the failure: skipped
  EXPECT_EQ(chain.runs[1], 1);
  EXPECT_EQ(chain.runs[2], 1);
  ASSERT_EQ(results.size(), 3u);
  EXPECT_TRUE(results[0].skipped);
  EXPECT_FALSE(results[2].skipped);
  RunStages(chain.stages, {});
  EXPECT_EQ(chain.runs[2], 1);  // everything up to date now
}

TEST(StageRunner, ChangedInputRerunsEverythingDownstream) {
  test::TempDir dir;
  Chain chain(dir.path());
  RunStages(chain.stages, {});
  // A newer input. File times are coarse (the kernel's clock tick): markers written within one tick of each other
  // compare equal, so every file of the first run is aged first (the run takes a few milliseconds) — the rerun's
  // markers are then newer than the old ones whatever the tick.
  const auto now = fs::file_time_type::clock::now();
  for (const auto& e : fs::recursive_directory_iterator(dir.path()))
    if (e.is_regular_file()) fs::last_write_time(e.path(), now - std::chrono::seconds(10));
  fs::last_write_time(dir / "input", now);
  RunStages(chain.stages, {});
  EXPECT_EQ(chain.runs[0], 2);
  // b and c see their input (a's marker) rewritten now, older than... it is newer than their markers.
  EXPECT_EQ(chain.runs[1], 2);
  EXPECT_EQ(chain.runs[2], 2);
}

TEST(StageRunner, FromAndUntilSelectStages) {
  test::TempDir dir;
  Chain chain(dir.path());
  RunStages(chain.stages, {"", "b"});
  EXPECT_EQ(chain.runs[2], 0);
  RunStages(chain.stages, {"b", ""});
  EXPECT_EQ(chain.runs[0], 1);
  EXPECT_EQ(chain.runs[1], 2);
  EXPECT_EQ(chain.runs[2], 1);
  try {
    RunStages(chain.stages, {"", "nope"});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown stage 'nope'"), std::string::npos);
  }
}

TEST(Reconstruct, MissingInputIsAClearError) {
  test::TempDir dir;
  ReconstructOptions o;
  o.inputs = {dir / "no-such-video.mp4"};
  o.workspace = dir / "ws";
  try {
    RunReconstruct(o);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no-such-video.mp4: no such file"), std::string::npos);
  }
  EXPECT_FALSE(fs::exists(dir / "ws"));
}

}  // namespace
}  // namespace fmv3d::pipeline
