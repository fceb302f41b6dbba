// Crash-safe workspaces, end to end on a small synthetic flight with KLV telemetry (every stage runs, terrain
// products included), in folders whose names have spaces and non-ASCII letters:
//  - `fmv3d reconstruct` killed with SIGKILL 20 times, twice inside each stage at a random moment of it, and
//    resumed each time: the final workspace holds the same files with the same bytes as an uninterrupted run
//    (stage summaries compared without their wall-clock seconds and with the workspace's path masked).
//  - a second process on a workspace in use refuses with a clear message; once the first is killed, the lock is
//    free again and the interrupted stage is redone to the same bytes.
//  - a file-size limit (RLIMIT_FSIZE, what a full disk looks like to the writer) stops the run with a clear error;
//    nothing finished earlier is lost, and the run resumes to the same result once the limit is lifted.
//  - inputs: a read-only input video works; a workspace that cannot be created and a missing input are clear
//    errors; an input video replaced after a run makes the next run start again from the frames stage.
// The uninterrupted reference run is made once for the suite: ctest runs these tests as one process
// (tests/CMakeLists.txt), so the flight is not reconstructed again for each test.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <set>
#include <thread>

#include "fmv3d/core/files.h"
#include "test_util.h"

namespace fmv3d::test {
namespace {

using Clock = std::chrono::steady_clock;

// fmv3d run as a child process whose stderr (the log) is read line by line.
class Child {
 public:
  explicit Child(const std::vector<std::string>& args, rlim_t file_size_limit = RLIM_INFINITY) {
    int fds[2];
    if (pipe(fds) != 0) throw std::runtime_error("pipe");
    pid_ = fork();
    if (pid_ == 0) {
      dup2(fds[1], 2);
      const int null = open("/dev/null", O_WRONLY);
      dup2(null, 1);
      close(fds[0]);
      close(fds[1]);
      if (file_size_limit != RLIM_INFINITY) {
        const rlimit lim{file_size_limit, file_size_limit};
        setrlimit(RLIMIT_FSIZE, &lim);
      }
      std::vector<char*> argv{const_cast<char*>(FMV3D_CLI)};
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(FMV3D_CLI, argv.data());
      _exit(127);
    }
    close(fds[1]);
    fd_ = fds[0];
  }
  ~Child() {
    if (pid_ > 0 && !reaped_) {
      kill(pid_, SIGKILL);
      Wait();
    }
    if (fd_ >= 0) close(fd_);
  }
  // Reads until a complete line matching `re` arrives (true) or the process closes its stderr (false).
  bool WaitForLine(const std::regex& re) { return WaitForLineUntil(re, Clock::time_point::max()); }
  // The same, but gives up (false) at `deadline`.
  bool WaitForLineUntil(const std::regex& re, Clock::time_point deadline) {
    while (true) {
      const size_t nl = buffer_.find('\n');
      if (nl != std::string::npos) {
        const std::string line = buffer_.substr(0, nl);
        buffer_.erase(0, nl + 1);
        log_ += line + "\n";
        if (std::regex_search(line, re)) return true;
        continue;
      }
      if (deadline != Clock::time_point::max()) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
        pollfd p{fd_, POLLIN, 0};
        if (left <= 0 || poll(&p, 1, static_cast<int>(left)) <= 0) return false;
      }
      char chunk[4096];
      const ssize_t n = read(fd_, chunk, sizeof chunk);
      if (n <= 0) return false;
      buffer_.append(chunk, static_cast<size_t>(n));
    }
  }
  void Kill() { kill(pid_, SIGKILL); }
  // Exit status (-signal when killed by one); drains the log first.
  int Wait() {
    while (WaitForLine(std::regex("$^"))) {
    }
    log_ += buffer_;
    buffer_.clear();
    int status = 0;
    waitpid(pid_, &status, 0);
    reaped_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  }
  const std::string& log() const { return log_; }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
  bool reaped_ = false;
  std::string buffer_, log_;
};

// Removes time figures from a stage summary: keys that name seconds ("seconds…", "cpu_seconds_…"), a number or a
// per-step object.
void DropTimings(nlohmann::json* j) {
  if (j->is_object()) {
    for (auto it = j->begin(); it != j->end();) {
      if (it.key().find("seconds") != std::string::npos)
        it = j->erase(it);
      else
        DropTimings(&it.value()), ++it;
    }
  } else if (j->is_array()) {
    for (auto& v : *j) DropTimings(&v);
  }
}

// Every regular file under `root` (relative path → content), as compared between two runs: the workspace's own
// path (summaries name their outputs) reads "WS", stage summaries lose their timings, and the lock file (the
// holder's pid) and report/timings.json (wall-clock seconds only) are left out.
std::map<std::string, std::string> Snapshot(const fs::path& root) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    if (!e.is_regular_file()) continue;
    const std::string rel = fs::relative(e.path(), root).string();
    if (rel == ".lock" || rel == "report/timings.json") continue;
    std::string bytes = core::ReadTextFile(e.path());
    if (e.path().extension() == ".json") {
      for (size_t at; (at = bytes.find(root.string())) != std::string::npos;)
        bytes.replace(at, root.string().size(), "WS");
      auto j = nlohmann::json::parse(bytes, nullptr, false);
      if (!j.is_discarded()) {
        DropTimings(&j);
        bytes = j.dump(1);
      }
    }
    out[rel] = bytes;
  }
  return out;
}

// Lists what differs between two workspaces (empty when they are the same).
std::string Differences(const fs::path& a, const fs::path& b) {
  const auto sa = Snapshot(a), sb = Snapshot(b);
  std::string diff;
  for (const auto& [rel, bytes] : sa) {
    const auto it = sb.find(rel);
    if (it == sb.end())
      diff += "only in the first: " + rel + "\n";
    else if (it->second != bytes)
      diff += "differs: " + rel + "\n";
  }
  for (const auto& [rel, bytes] : sb)
    if (!sa.count(rel)) diff += "only in the second: " + rel + "\n";
  return diff;
}

struct StageTime {
  std::string name;
  double seconds;
};

// The stages a log shows as run, in order, with their durations ("[3/10] match done in 1.2 s").
std::vector<StageTime> StagesRun(const std::string& log) {
  std::vector<StageTime> out;
  static const std::regex done(R"(\[\d+/\d+\] (\w+) done in ([0-9.]+) s)");
  for (auto it = std::sregex_iterator(log.begin(), log.end(), done); it != std::sregex_iterator(); ++it)
    out.push_back({(*it)[1].str(), std::stod((*it)[2].str())});
  return out;
}

class CrashSafety : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // The LAS header's creation day follows SOURCE_DATE_EPOCH, as every run here does: runs on either side of
    // midnight (GMT) would otherwise differ in it.
    setenv("SOURCE_DATE_EPOCH", "1767225600", 1);
    dir_ = new TempDir("fmv3d-crash safety ü");
    const fs::path synth = *dir_ / "synth";
    const auto r = RunCli(
        "-q synth --scene building --path orbit --frames 90 --fps 10 --size 320x180 --klv"
        " --seed 5 -o '" +
        synth.string() + "'");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    // The input keeps a name with a space and non-ASCII letters, and is read-only.
    video_ = new fs::path(*dir_ / "vidéo du vol.ts");
    fs::rename(synth / "flight.ts", *video_);
    fs::permissions(*video_, fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
    reference_ = new fs::path(*dir_ / "référence ws");
    Child ref(Args(*reference_));
    ASSERT_EQ(ref.Wait(), 0) << ref.log();
    *stages_ = StagesRun(ref.log());
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete video_;
    delete reference_;
  }
  static std::vector<std::string> Args(const fs::path& ws) {
    return {"reconstruct", video_->string(), "-o", ws.string(), "--fast", "--no-report"};
  }

  static TempDir* dir_;
  static fs::path* video_;
  static fs::path* reference_;
  static std::vector<StageTime>* stages_;
};
TempDir* CrashSafety::dir_ = nullptr;
fs::path* CrashSafety::video_ = nullptr;
fs::path* CrashSafety::reference_ = nullptr;
std::vector<StageTime>* CrashSafety::stages_ = new std::vector<StageTime>;

TEST_F(CrashSafety, TwentyKillsAcrossEveryStageThenTheSameWorkspace) {
  ASSERT_GE(stages_->size(), 10u) << "the reference run should run every stage";
  const fs::path ws = *dir_ / "killed ws ñ";
  std::mt19937 rng(26);
  // The reference's stage times can be longer than this run's (another load on the machine): a kill moment
  // drawn past the stage's end would let the rest of the run finish unkilled. When a stage ends before its
  // kill moment, the process is killed at once (in the next stage) and later moments are drawn shorter.
  double time_scale = 1;
  int kills = 0;
  std::set<std::string> stages_killed;
  for (const auto& stage : *stages_) {
    for (int k = 0; k < 2; ++k) {
      Child run(Args(ws));
      // Wait until this stage starts (earlier ones are resumed or skipped), then kill at a random moment of it.
      // A stage shorter than the kill delay may have finished in the previous run: then it is skipped, and this
      // kill lands in the next stage that runs.
      ASSERT_TRUE(run.WaitForLine(std::regex("\\] " + stage.name + "( \\.\\.\\.|: up to date, skipped)$")))
          << run.log();
      const double at = std::uniform_real_distribution<double>(0, std::max(0.05, time_scale * stage.seconds))(rng);
      const auto moment = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(at));
      if (run.WaitForLineUntil(std::regex("\\] " + stage.name + " done"), moment)) time_scale *= 0.7;
      run.Kill();
      const int status = run.Wait();
      if (status == -SIGKILL) {
        ++kills;
        if (run.log().find("] " + stage.name + " done") == std::string::npos) stages_killed.insert(stage.name);
      }
    }
  }
  Child last(Args(ws));
  ASSERT_EQ(last.Wait(), 0) << last.log();
  std::cout << kills << " kills, inside " << stages_killed.size() << " of " << stages_->size() << " stages\n";
  EXPECT_GE(kills, 20);
  EXPECT_GE(stages_killed.size(), stages_->size() - 2) << "most kills should land inside their stage";
  EXPECT_EQ(Differences(*reference_, ws), "");
}

TEST_F(CrashSafety, SecondProcessRefusedAndKilledHolderLeavesNoStaleLock) {
  const fs::path ws = *dir_ / "locked ws";
  Child first(Args(ws));
  ASSERT_TRUE(first.WaitForLine(std::regex("\\] features \\.\\.\\.$"))) << first.log();
  Child second(Args(ws));
  EXPECT_EQ(second.Wait(), 1);
  EXPECT_NE(second.log().find("in use by another fmv3d process"), std::string::npos) << second.log();
  first.Kill();
  EXPECT_EQ(first.Wait(), -SIGKILL);
  // The lock is free again: a third process takes it and redoes the interrupted stage to the reference's bytes
  // (resuming to the whole reference is what the twenty kills above check).
  auto args = Args(ws);
  args.insert(args.end(), {"--until", "features"});
  Child third(args);
  EXPECT_EQ(third.Wait(), 0) << third.log();
  const auto resumed = Snapshot(ws), reference = Snapshot(*reference_);
  size_t compared = 0;
  for (const auto& [rel, bytes] : reference)
    if (rel.rfind("features/", 0) == 0) {
      ++compared;
      const auto it = resumed.find(rel);
      ASSERT_NE(it, resumed.end()) << rel << " missing after the resumed run";
      EXPECT_EQ(it->second, bytes) << rel;
    }
  EXPECT_GT(compared, 0u);
}

// The largest file of the stages up to the depth maps of the reference run.
uintmax_t LargestFileBeforeFusion(const fs::path& ws) {
  uintmax_t largest = 0;
  for (const char* dir : {"frames", "features", "matches", "sparse", "geo", "dense/maps"})
    if (fs::is_directory(ws / dir))
      for (const auto& e : fs::recursive_directory_iterator(ws / dir))
        if (e.is_regular_file()) largest = std::max(largest, e.file_size());
  return largest;
}

TEST_F(CrashSafety, FileSizeLimitIsAClearErrorAndResumeCompletes) {
  const fs::path ws = *dir_ / "full disk ws";
  // A per-file limit that every file up to the depth maps fits and the fused cloud does not: the run fails in
  // the dense stage, after sparse.
  const uintmax_t limit = LargestFileBeforeFusion(*reference_) * 21 / 20;
  ASSERT_GT(fs::file_size(*reference_ / "dense/fused.ply"), limit);
  Child limited(Args(ws), static_cast<rlim_t>(limit));
  EXPECT_EQ(limited.Wait(), 1) << limited.log();
  EXPECT_NE(limited.log().find("File too large"), std::string::npos) << limited.log();
  // What finished before the failure is intact: every file present is the reference's.
  const auto before = Snapshot(ws), reference = Snapshot(*reference_);
  ASSERT_TRUE(before.count("sparse/images.txt")) << "the run should fail after the sparse stage";
  for (const auto& [rel, bytes] : before)
    if (rel.rfind(".stages/", 0) != 0) {
      ASSERT_TRUE(reference.count(rel)) << rel << " is not a finished output";
      EXPECT_EQ(bytes, reference.at(rel)) << rel;
    }
  Child resumed(Args(ws));
  ASSERT_EQ(resumed.Wait(), 0) << resumed.log();
  EXPECT_NE(resumed.log().find("features: up to date, skipped"), std::string::npos) << resumed.log();
  EXPECT_EQ(Differences(*reference_, ws), "");
}

TEST_F(CrashSafety, BadPathsAreClearErrors) {
  const auto missing = RunCli("reconstruct '" + (*dir_ / "no such vidéo.ts").string() + "' -o '" +
                              (*dir_ / "ws missing").string() + "'");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.err.find("no such vidéo.ts: no such file or folder"), std::string::npos) << missing.err;
  // A workspace under a regular file cannot be created (the same for a folder without write permission).
  const auto blocked = RunCli("reconstruct '" + video_->string() + "' -o '" + (*video_ / "ws").string() + "'");
  EXPECT_EQ(blocked.exit_code, 1);
  EXPECT_NE(blocked.err.find("fmv3d: error: "), std::string::npos) << blocked.err;
  EXPECT_NE(blocked.err.find("cannot create directory"), std::string::npos) << blocked.err;
}

TEST_F(CrashSafety, ReplacedInputVideoRerunsFromFrames) {
  const fs::path ws = *dir_ / "replaced ws";
  fs::copy(*reference_, ws, fs::copy_options::recursive);
  fs::remove(ws / ".lock");
  // Another flight (other seed, fewer frames) takes the video's name, as a copy over it would.
  const fs::path other = *dir_ / "other";
  const auto r = RunCli(
      "-q synth --scene building --path orbit --frames 60 --fps 10 --size 320x180 --klv"
      " --seed 9 -o '" +
      other.string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path video = *dir_ / "replaced vidéo.ts";
  fs::copy_file(*video_, video);
  fs::permissions(video, fs::perms::owner_write, fs::perm_options::add);
  // Only the frames stage and the next one are looked at: the later stages need not run.
  std::vector<std::string> args = Args(ws);
  args[1] = video.string();
  args.insert(args.end(), {"--until", "features"});
  {
    Child first(args);  // the workspace's frames now name another input: the frames stage runs again
    ASSERT_EQ(first.Wait(), 0) << first.log();
  }
  const std::string frames_before = core::ReadTextFile(ws / "frames/frames.json");
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  fs::copy_file(other / "flight.ts", video, fs::copy_options::overwrite_existing);
  Child second(args);
  ASSERT_EQ(second.Wait(), 0) << second.log();
  const auto stages = StagesRun(second.log());
  ASSERT_FALSE(stages.empty()) << second.log();
  EXPECT_EQ(stages.front().name, "frames") << second.log();
  EXPECT_NE(core::ReadTextFile(ws / "frames/frames.json"), frames_before);
}

}  // namespace
}  // namespace fmv3d::test
