#include "fmv3d/core/logging.h"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>

#include "fmv3d/core/progress_log.h"

namespace fmv3d::core {

void SetupLogging(int verbosity) {
  // Logs go to stderr so that stdout stays clean for machine-readable output (e.g. `fmv3d klv`).
  auto logger = spdlog::stderr_color_mt("fmv3d");
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("[%H:%M:%S] %^%l%$ %v");
  spdlog::set_level(verbosity < 0 ? spdlog::level::err : verbosity == 0 ? spdlog::level::info : spdlog::level::debug);
}

Progress::Progress(std::string label, size_t total)
    : label_(std::move(label)), total_(total), start_(std::chrono::steady_clock::now()), last_draw_(start_) {
  tty_ = isatty(STDERR_FILENO) && spdlog::default_logger()->should_log(spdlog::level::info);
}

Progress::~Progress() { Finish(); }

void Progress::Add(size_t n) {
  const size_t done = done_ += n;
  std::lock_guard<std::mutex> lock(mutex_);
  Draw(done, false);
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  Draw(done_.load(), true);
}

void Progress::Draw(size_t done, bool final) {
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double frac = total_ ? static_cast<double>(done) / total_ : 1.0;
  // The progress log (progress_log.h) gets its own throttled line.
  AppendProgressUpdate(label_, done, total_, frac > 0 ? elapsed * (1 - frac) / frac : 0.0, final);
  if (tty_) {
    if (!final && std::chrono::duration<double>(now - last_draw_).count() < 0.1) return;
    last_draw_ = now;
    const int width = 30, filled = static_cast<int>(frac * width);
    const double eta = frac > 0 ? elapsed * (1 - frac) / frac : 0;
    std::fprintf(stderr, "\r%-12s [%s%s] %zu/%zu  %.0fs elapsed, ETA %.0fs ", label_.c_str(),
                 std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(), done, total_, elapsed,
                 eta);
    if (final) std::fprintf(stderr, "\n");
    std::fflush(stderr);
    return;
  }
  const int decile = static_cast<int>(frac * 10);
  if (decile > last_decile_ && (decile > 0 || final)) {
    last_decile_ = decile;
    spdlog::info("{}: {}/{} ({:.0f}%, {:.1f} s)", label_, done, total_, frac * 100, elapsed);
  }
}

}  // namespace fmv3d::core
