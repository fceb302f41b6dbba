// A job started through the API on uploaded synthetic frames: it runs `fmv3d reconstruct` to the sparse model,
// its progress arrives on the event stream (snapshot on connect, job / progress / log events), and resume,
// the one-job-per-workspace rule and stop work.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>

#include "fmv3d/core/files.h"
#include "server_fixture.h"

namespace fmv3d::server::test {
namespace {

namespace fs = std::filesystem;

// Reads /api/events in a thread and keeps every parsed event.
class EventReader {
 public:
  explicit EventReader(const RunningServer& s) : client_(s.Client()) {
    thread_ = std::thread([this] {
      client_->Get("/api/events", [this](const char* data, size_t n) {
        std::lock_guard<std::mutex> lock(mutex_);
        buffer_.append(data, n);
        for (size_t end; (end = buffer_.find("\n\n")) != std::string::npos; buffer_.erase(0, end + 2)) {
          const std::string block = buffer_.substr(0, end);
          if (block.rfind("event: ", 0) != 0) continue;  // keep-alive comment
          const size_t nl = block.find('\n');
          events_.push_back({block.substr(7, nl - 7), nlohmann::json::parse(block.substr(nl + 7), nullptr, false)});
        }
        cv_.notify_all();
        return !stop_;
      });
    });
  }
  ~EventReader() {
    stop_ = true;
    client_->stop();
    thread_.join();
  }
  // Waits until pred(events) holds or the timeout passes; returns whether it held.
  bool WaitFor(const std::function<bool(const std::vector<std::pair<std::string, nlohmann::json>>&)>& pred,
               std::chrono::seconds timeout) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, timeout, [&] { return pred(events_); });
  }
  std::vector<std::pair<std::string, nlohmann::json>> events() {
    std::lock_guard<std::mutex> lock(mutex_);
    return events_;
  }

 private:
  std::unique_ptr<httplib::Client> client_;
  std::thread thread_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::string buffer_;
  std::vector<std::pair<std::string, nlohmann::json>> events_;
  std::atomic<bool> stop_{false};
};

bool JobInState(const std::vector<std::pair<std::string, nlohmann::json>>& events, const std::string& id,
                const std::string& state) {
  for (const auto& [type, data] : events)
    if (type == "job" && data.value("id", "") == id && data.value("state", "") == state) return true;
  return false;
}

TEST(Jobs, RunFromAnUploadWithLiveProgressThenResumeAndStop) {
  fmv3d::test::TempDir tmp("api-job");
  fs::create_directories(tmp / "root");
  // Ten still frames (a video this short would give the keyframe selector too few frames to model).
  const auto synth = fmv3d::test::RunCli(
      "synth --frames 10 --size 320x180 --format png --supersample 1 --no-scene -o " + (tmp / "synth").string());
  ASSERT_EQ(synth.exit_code, 0) << synth.err;
  httplib::MultipartFormDataItems items;
  for (const auto& e : fs::directory_iterator(tmp / "synth" / "frames"))
    items.push_back({"file", core::ReadTextFile(e.path()), e.path().filename().string(), "image/png"});
  ASSERT_EQ(items.size(), 10u);

  ServerOptions o;
  o.ws_root = tmp / "root";
  o.executable = FMV3D_CLI;
  RunningServer s(o);
  auto c = s.Client();
  EventReader events(s);
  ASSERT_TRUE(events.WaitFor([](const auto& ev) { return !ev.empty(); }, std::chrono::seconds(10)));
  EXPECT_EQ(events.events()[0].first, "snapshot");
  EXPECT_TRUE(events.events()[0].second.is_array());

  ASSERT_EQ(c->Post("/api/workspaces", R"({"name": "flight"})", "application/json")->status, 201);
  auto r = c->Post("/api/workspaces/flight/uploads", items);
  ASSERT_EQ(r->status, 201) << r->body;
  EXPECT_EQ(Json(r)["paths"].size(), 10u);

  // The uploads folder is the input; the run stops after the sparse model (then writes its report).
  r = c->Post("/api/workspaces/flight/jobs", R"({"inputs": ["uploads"], "until": "sparse", "fast": true})",
              "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  const std::string id = Json(r)["id"];
  EXPECT_EQ(Json(r)["state"], "running");
  EXPECT_EQ(Json(r)["workspace"], "flight");
  // A second job on the same workspace while it runs: 409.
  EXPECT_EQ(c->Post("/api/workspaces/flight/jobs", R"({})", "application/json")->status, 409);

  ASSERT_TRUE(events.WaitFor([&](const auto& ev) { return JobInState(ev, id, "done") || JobInState(ev, id, "failed"); },
                             std::chrono::seconds(600)));
  const auto job = Json(c->Get("/api/jobs/" + id));
  ASSERT_EQ(job["state"], "done") << job.dump(1);
  EXPECT_EQ(job["exit_code"], 0);
  EXPECT_TRUE(job["finished"].is_number());
  EXPECT_FALSE(job["log"].empty());
  std::map<std::string, std::string> stage_state;
  for (const auto& st : job["stages"]) stage_state[st["name"]] = st["state"];
  for (const char* st : {"frames", "features", "match", "sparse", "report"}) EXPECT_EQ(stage_state[st], "done") << st;
  EXPECT_EQ(stage_state["dense"], "pending");

  // The stream carried stage changes, per-stage progress with counts and ETA, and the log.
  int progress = 0, logs = 0;
  std::set<std::string> started;
  for (const auto& [type, data] : events.events()) {
    if (type == "progress" && data["job"] == id) {
      ++progress;
      EXPECT_TRUE(data["total"].is_number() && data["done"].is_number() && data["eta_s"].is_number());
      EXPECT_LE(data["done"].get<double>(), data["total"].get<double>());
    }
    if (type == "log" && data["job"] == id) ++logs;
    if (type == "job" && data["id"] == id && data["stage"].is_string()) started.insert(data["stage"]);
  }
  EXPECT_GT(progress, 0);
  EXPECT_GT(logs, 0);
  EXPECT_TRUE(started.count("features") && started.count("sparse"));

  // The workspace now lists its stages from the markers, and its job.
  auto w = Json(c->Get("/api/workspaces/flight"));
  EXPECT_EQ(w["job"]["id"], id);
  EXPECT_EQ(w["frames"].get<int>(), 10);
  EXPECT_GE(w["registered"].get<int>(), 4);
  for (const auto& st : w["stages"]) {
    if (st["name"] == "sparse") {
      EXPECT_EQ(st["state"], "done");
    }
  }

  // Resume from project.json's inputs (none given), re-running from dense, then stop it.
  r = c->Post("/api/workspaces/flight/jobs", R"({"from": "dense", "fast": true})", "application/json");
  ASSERT_EQ(r->status, 202) << r->body;
  const std::string id2 = Json(r)["id"];
  EXPECT_NE(id2, id);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  r = c->Post("/api/jobs/" + id2 + "/stop", "", "application/json");
  ASSERT_EQ(r->status, 200);
  ASSERT_TRUE(events.WaitFor([&](const auto& ev) { return JobInState(ev, id2, "stopped"); }, std::chrono::seconds(20)));
  const auto stopped = Json(c->Get("/api/jobs/" + id2));
  EXPECT_EQ(stopped["state"], "stopped");
  EXPECT_NE(stopped["exit_code"], 0);
  EXPECT_EQ(Json(c->Get("/api/jobs")).size(), 2u);

  // A page reloaded now gets both jobs in its snapshot.
  EventReader again(s);
  ASSERT_TRUE(again.WaitFor([](const auto& ev) { return !ev.empty(); }, std::chrono::seconds(10)));
  EXPECT_EQ(again.events()[0].first, "snapshot");
  EXPECT_EQ(again.events()[0].second.size(), 2u);

  // A server started afresh on the same root rebuilds both jobs from the workspace's job files, and numbers
  // its next job after them.
  RunningServer restarted(o);
  auto c2 = restarted.Client();
  const auto history = Json(c2->Get("/api/jobs"));
  ASSERT_EQ(history.size(), 2u) << history.dump(1);
  EXPECT_EQ(history[0]["id"], id);
  EXPECT_EQ(history[0]["state"], "done");
  EXPECT_EQ(history[0]["exit_code"], 0);
  EXPECT_EQ(history[1]["id"], id2);
  EXPECT_EQ(history[1]["state"], "stopped");
  EXPECT_EQ(history[0]["started"], job["started"]);
  for (const auto& st : history[0]["stages"]) {
    if (st["name"] == "sparse" || st["name"] == "report") {
      EXPECT_EQ(st["state"], "done") << st["name"];
    }
  }
  const auto old = Json(c2->Get("/api/jobs/" + id));
  EXPECT_FALSE(old["log"].empty());
  EXPECT_EQ(old["log"].back(), job["log"].back());
  EXPECT_EQ(Json(c2->Get("/api/workspaces/flight"))["job"]["id"], id2);
  r = c2->Post("/api/workspaces/flight/jobs", R"({"from": "dense", "fast": true})", "application/json");
  ASSERT_EQ(r->status, 202) << r->body;
  const std::string id3 = Json(r)["id"];
  EXPECT_GT(std::stoi(id3), std::max(std::stoi(id), std::stoi(id2)));
  c2->Post("/api/jobs/" + id3 + "/stop", "", "application/json");
}

}  // namespace
}  // namespace fmv3d::server::test
