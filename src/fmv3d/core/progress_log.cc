#include "fmv3d/core/progress_log.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>

#include "fmv3d/core/error.h"

namespace fmv3d::core {

namespace {
std::mutex g_mutex;
std::FILE* g_file = nullptr;
std::atomic<bool> g_open{false};
}  // namespace

void OpenProgressLog(const std::filesystem::path& path) {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (g_file) std::fclose(g_file);
  g_file = std::fopen(path.c_str(), "a");
  if (!g_file) throw Error(path.string() + ": cannot open the progress log for writing");
  g_open = true;
}

void CloseProgressLog() {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (g_file) std::fclose(g_file);
  g_file = nullptr;
  g_open = false;
}

bool ProgressLogOpen() { return g_open.load(); }

void AppendProgressEvent(nlohmann::json event) {
  if (!g_open.load()) return;
  event["t"] = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  const std::string line = event.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
  std::lock_guard<std::mutex> lock(g_mutex);
  if (!g_file) return;
  std::fputs(line.c_str(), g_file);
  std::fflush(g_file);
}

}  // namespace fmv3d::core
