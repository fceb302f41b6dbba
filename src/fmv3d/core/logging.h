// Logging (spdlog) and progress reporting for long stages.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <string>

namespace fmv3d::core {

// verbosity: -1 quiet (errors only), 0 info, 1 debug.
void SetupLogging(int verbosity);

// Thread-safe progress for a loop of `total` steps. On a terminal it redraws one bar with an ETA on stderr;
// otherwise (CI, pipes, logs) it writes a plain log line every 10%. Silent when logging is quiet.
class Progress {
 public:
  Progress(std::string label, size_t total);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;
  void Add(size_t n = 1);
  void Finish();

 private:
  void Draw(size_t done, bool final);
  std::string label_;
  size_t total_;
  std::atomic<size_t> done_{0};
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  int last_decile_ = -1;
  bool tty_ = false;
  bool finished_ = false;
};

}  // namespace fmv3d::core
