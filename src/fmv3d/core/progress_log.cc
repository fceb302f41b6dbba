#include "fmv3d/core/progress_log.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <map>
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

void AppendProgressUpdate(const std::string& label, size_t done, size_t total, double eta_s, bool final) {
  if (!g_open.load()) return;
  static std::mutex mutex;
  static std::map<std::string, std::chrono::steady_clock::time_point> last;
  {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> lock(mutex);
    auto it = last.find(label);
    if (!final && it != last.end() && std::chrono::duration<double>(now - it->second).count() < 0.5) return;
    last[label] = now;
  }
  AppendProgressEvent({{"event", "progress"}, {"label", label}, {"done", done}, {"total", total}, {"eta_s", eta_s}});
}

}  // namespace fmv3d::core
