#include "fmv3d/server/events.h"

namespace fmv3d::server {

std::string FormatSse(const Event& e) { return "event: " + e.type + "\ndata: " + e.data + "\n\n"; }

void EventHub::Publish(const std::string& type, const nlohmann::json& data) {
  std::string text = data.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    events_.push_back({++last_seq_, type, std::move(text)});
    while (events_.size() > history_) events_.pop_front();
  }
  cv_.notify_all();
}

uint64_t EventHub::LastSeq() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_seq_;
}

std::vector<Event> EventHub::WaitAfter(uint64_t after, std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return closed_ || last_seq_ > after; });
  std::vector<Event> out;
  if (closed_) return out;
  for (const auto& e : events_)
    if (e.seq > after) out.push_back(e);
  return out;
}

void EventHub::Close() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }
  cv_.notify_all();
}

bool EventHub::closed() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return closed_;
}

bool EventHub::TryAddReader(int max) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (readers_ >= max) return false;
  ++readers_;
  return true;
}

void EventHub::RemoveReader() {
  std::lock_guard<std::mutex> lock(mutex_);
  --readers_;
}

}  // namespace fmv3d::server
