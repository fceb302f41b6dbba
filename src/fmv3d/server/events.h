// The server's event stream (GET /api/events): a bounded history of numbered events that any number of SSE
// connections read at their own pace. Publishers never block on a slow reader: a reader that falls more than
// the history behind skips the events it missed (the next `job` event or a reload's `snapshot` catches it up).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace fmv3d::server {

struct Event {
  uint64_t seq = 0;
  std::string type;  // snapshot | job | progress | log
  std::string data;  // one line of JSON
};

// "event: TYPE\ndata: JSON\n\n" (the data is a single line: JSON has no raw newlines).
std::string FormatSse(const Event& e);

class EventHub {
 public:
  explicit EventHub(size_t history = 2000) : history_(history) {}
  void Publish(const std::string& type, const nlohmann::json& data);
  uint64_t LastSeq() const;
  // The events numbered after `after`, waiting up to `timeout` for one; empty on timeout or once closed.
  std::vector<Event> WaitAfter(uint64_t after, std::chrono::milliseconds timeout);
  // Wakes every reader for good (server shutdown).
  void Close();
  bool closed() const;
  // Readers hold a worker thread each: at most `max` at once (false: refuse the connection).
  bool TryAddReader(int max);
  void RemoveReader();

 private:
  size_t history_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Event> events_;
  uint64_t last_seq_ = 0;
  bool closed_ = false;
  int readers_ = 0;
};

}  // namespace fmv3d::server
