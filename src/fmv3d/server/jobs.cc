#include "fmv3d/server/jobs.h"

#include <signal.h>

#include <algorithm>
#include <chrono>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/server/process.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

namespace {
double Now() { return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count(); }
bool Finished(JobState s) { return s == JobState::kDone || s == JobState::kFailed || s == JobState::kStopped; }

// Reads what was appended to `path` since `*offset`, splits it into complete lines (the rest waits in *partial).
std::vector<std::string> ReadNewLines(const fs::path& path, uint64_t* offset, std::string* partial) {
  std::vector<std::string> lines;
  std::ifstream in(path, std::ios::binary);
  if (!in) return lines;
  in.seekg(0, std::ios::end);
  const uint64_t size = static_cast<uint64_t>(in.tellg());
  if (size <= *offset) return lines;
  const uint64_t n = std::min<uint64_t>(size - *offset, 4 << 20);  // at most 4 MB per poll
  std::string chunk(n, '\0');
  in.seekg(static_cast<std::streamoff>(*offset));
  in.read(chunk.data(), static_cast<std::streamsize>(n));
  *offset += static_cast<uint64_t>(in.gcount());
  chunk.resize(static_cast<size_t>(in.gcount()));
  *partial += chunk;
  size_t start = 0;
  for (size_t nl; (nl = partial->find('\n', start)) != std::string::npos; start = nl + 1) {
    std::string line = partial->substr(start, nl - start);
    // A terminal progress bar redraws with '\r': keep the last state of the line.
    const size_t cr = line.find_last_of('\r', line.size() >= 1 ? line.size() - 1 : 0);
    if (cr != std::string::npos && cr + 1 < line.size()) line = line.substr(cr + 1);
    while (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(std::move(line));
  }
  partial->erase(0, start);
  if (partial->size() > (1 << 20)) partial->clear();  // a runaway line without newline
  return lines;
}
}  // namespace

const char* JobStateName(JobState s) {
  switch (s) {
    case JobState::kQueued:
      return "queued";
    case JobState::kRunning:
      return "running";
    case JobState::kDone:
      return "done";
    case JobState::kFailed:
      return "failed";
    case JobState::kStopped:
      return "stopped";
  }
  return "queued";
}

std::optional<JobState> ParseJobState(std::string_view name) {
  for (const JobState s :
       {JobState::kQueued, JobState::kRunning, JobState::kDone, JobState::kFailed, JobState::kStopped})
    if (name == JobStateName(s)) return s;
  return std::nullopt;
}

std::vector<std::string> ReconstructArgv(const fs::path& executable, const std::vector<fs::path>& inputs,
                                         const fs::path& ws, const JobRequest& r, const fs::path& progress_json) {
  std::vector<std::string> argv = {executable.string(), "reconstruct"};
  for (const auto& in : inputs) argv.push_back(in.string());
  argv.insert(argv.end(), {"-o", ws.string()});
  if (!r.from.empty() && r.from != "report") argv.insert(argv.end(), {"--from", r.from});
  if (!r.until.empty() && r.until != "report") argv.insert(argv.end(), {"--until", r.until});
  if (r.fast) argv.push_back("--fast");
  argv.insert(argv.end(), {"--progress-json", progress_json.string()});
  return argv;
}

JobManager::JobManager(JobManagerOptions options, EventHub* hub) : options_(std::move(options)), hub_(hub) {
  monitor_ = std::thread([this] { MonitorLoop(); });
}

JobManager::~JobManager() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto& j : jobs_)
      if (j->state == JobState::kRunning) {
        ::kill(j->pid, SIGTERM);
        if (j->stop_requested == 0) j->stop_requested = Now();
      }
  }
  // The monitor escalates to SIGKILL and reaps; wait for every child to be gone.
  for (int i = 0; i < 1000; ++i) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      bool any = false;
      for (auto& j : jobs_) any = any || j->state == JobState::kRunning;
      if (!any) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  quit_ = true;
  if (monitor_.joinable()) monitor_.join();
}

nlohmann::json JobManager::Start(const std::string& workspace, const fs::path& ws_dir,
                                 const std::vector<fs::path>& inputs, const JobRequest& request) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& j : jobs_)
    if (j->workspace == workspace && !Finished(j->state))
      throw RequestError(409, "workspace '" + workspace + "' already runs job " + j->id);
  auto job = std::make_unique<Job>();
  job->id = std::to_string(next_id_++);
  job->workspace = workspace;
  const fs::path dir = ws_dir / "jobs";
  try {
    core::EnsureDirectory(dir);
  } catch (const Error& e) {
    throw RequestError(500, e.what());
  }
  job->log_path = dir / (job->id + "-" + std::to_string(static_cast<long long>(Now())) + ".log");
  job->progress_path = fs::path(job->log_path).replace_extension(".progress.jsonl");
  for (const auto& name : StageNames()) job->stages.push_back({name});
  const auto argv = ReconstructArgv(options_.executable, inputs, ws_dir, request, job->progress_path);
  try {
    job->pid = SpawnProcess(argv, job->log_path);
  } catch (const Error& e) {
    throw RequestError(500, e.what());
  }
  job->state = JobState::kRunning;
  job->started = Now();
  std::string cmd;
  for (const auto& a : argv) cmd += (cmd.empty() ? "" : " ") + a;
  job->log.push_back("$ " + cmd);
  nlohmann::json j = ToJson(*job, false);
  jobs_.push_back(std::move(job));
  Publish("job", j);
  return j;
}

void JobManager::RequireIdle(const std::string& workspace) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& j : jobs_)
    if (j->workspace == workspace && !Finished(j->state))
      throw RequestError(409, "workspace '" + workspace + "' already runs job " + j->id);
}

nlohmann::json JobManager::List() const {
  std::lock_guard<std::mutex> lock(mutex_);
  nlohmann::json out = nlohmann::json::array();
  for (const auto& j : jobs_) out.push_back(ToJson(*j, false));
  return out;
}

std::optional<nlohmann::json> JobManager::Get(const std::string& id, bool with_log) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& j : jobs_)
    if (j->id == id) return ToJson(*j, with_log);
  return std::nullopt;
}

std::optional<nlohmann::json> JobManager::Stop(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto& j : jobs_)
    if (j->id == id) {
      if (j->state == JobState::kRunning && j->stop_requested == 0) {
        j->stop_requested = Now();
        ::kill(j->pid, SIGTERM);
      }
      return ToJson(*j, false);
    }
  return std::nullopt;
}

nlohmann::json JobManager::LatestFor(const std::string& workspace) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = jobs_.rbegin(); it != jobs_.rend(); ++it)
    if ((*it)->workspace == workspace) return ToJson(**it, false);
  return nullptr;
}

std::map<std::string, StageState> JobManager::StageOverrides(const std::string& workspace) const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::map<std::string, StageState> out;
  for (auto it = jobs_.rbegin(); it != jobs_.rend(); ++it)
    if ((*it)->workspace == workspace) {
      for (const auto& s : (*it)->stages)
        if (s.state == StageState::kRunning || s.state == StageState::kFailed) out[s.name] = s.state;
      break;
    }
  return out;
}

nlohmann::json JobManager::ToJson(const Job& job, bool with_log) const {
  nlohmann::json stages = nlohmann::json::array();
  for (const auto& s : job.stages)
    stages.push_back({{"name", s.name},
                      {"state", StageStateName(s.state)},
                      {"done", s.done},
                      {"total", s.total},
                      {"eta_s", s.eta_s}});
  nlohmann::json j = {{"id", job.id},
                      {"workspace", job.workspace},
                      {"state", JobStateName(job.state)},
                      {"stage", job.stage.empty() ? nlohmann::json() : nlohmann::json(job.stage)},
                      {"stages", stages},
                      {"started", job.started},
                      {"finished", job.finished > 0 ? nlohmann::json(job.finished) : nlohmann::json()},
                      {"exit_code", job.exit_code ? nlohmann::json(*job.exit_code) : nlohmann::json()}};
  if (with_log) j["log"] = nlohmann::json(std::vector<std::string>(job.log.begin(), job.log.end()));
  return j;
}

JobManager::StageProgress* JobManager::FindStage(Job& job, const std::string& name) {
  for (auto& s : job.stages)
    if (s.name == name) return &s;
  job.stages.push_back({name});
  return &job.stages.back();
}

void JobManager::HandleLogLine(Job& job, const std::string& line) {
  job.log.push_back(line);
  while (job.log.size() > options_.log_lines) job.log.pop_front();
  Publish("log", {{"job", job.id}, {"line", line}});
}

void JobManager::HandleProgressLine(Job& job, const std::string& line) {
  const nlohmann::json e = nlohmann::json::parse(line, nullptr, false);
  if (e.is_discarded() || !e.is_object() || !e.contains("event") || !e["event"].is_string()) return;
  const std::string type = e["event"].get<std::string>();
  if (type == "stages" && e.contains("stages") && e["stages"].is_array()) {
    std::vector<StageProgress> stages;
    for (const auto& n : e["stages"])
      if (n.is_string()) stages.push_back({n.get<std::string>()});
    stages.push_back({"report"});
    job.stages = std::move(stages);
    Publish("job", ToJson(job, false));
  } else if (type == "stage" && e.contains("stage") && e["stage"].is_string() && e.contains("state") &&
             e["state"].is_string()) {
    const std::string name = e["stage"].get<std::string>(), event = e["state"].get<std::string>();
    // The stage runner's events: start, done, skipped, failed.
    const std::optional<StageState> state = event == "start" ? StageState::kRunning : ParseStageState(event);
    if (!state) return;
    StageProgress* s = FindStage(job, name);
    s->state = *state;
    if (*state == StageState::kRunning) job.stage = name;
    if (*state == StageState::kDone || *state == StageState::kSkipped) {
      s->eta_s = 0;
      if (s->total > 0) s->done = s->total;
    }
    Publish("job", ToJson(job, false));
  } else if (type == "progress" && !job.stage.empty()) {
    StageProgress* s = FindStage(job, job.stage);
    s->done = e.value("done", 0.0);
    s->total = e.value("total", 0.0);
    s->eta_s = e.value("eta_s", 0.0);
    Publish("progress", {{"job", job.id},
                         {"stage", job.stage},
                         {"label", e.value("label", std::string())},
                         {"done", s->done},
                         {"total", s->total},
                         {"eta_s", s->eta_s}});
  }
}

void JobManager::Poll(Job& job) {
  for (const auto& line : ReadNewLines(job.progress_path, &job.progress_offset, &job.progress_partial))
    HandleProgressLine(job, line);
  for (const auto& line : ReadNewLines(job.log_path, &job.log_offset, &job.log_partial)) HandleLogLine(job, line);
  const auto code = PollExit(job.pid);
  if (!code) {
    if (job.stop_requested > 0 && !job.killed && Now() - job.stop_requested > options_.stop_grace_s) {
      ::kill(job.pid, SIGKILL);
      job.killed = true;
    }
    return;
  }
  // Read what the child wrote in its last moments, then close the job.
  for (const auto& line : ReadNewLines(job.progress_path, &job.progress_offset, &job.progress_partial))
    HandleProgressLine(job, line);
  for (const auto& line : ReadNewLines(job.log_path, &job.log_offset, &job.log_partial)) HandleLogLine(job, line);
  if (!job.log_partial.empty()) HandleLogLine(job, job.log_partial), job.log_partial.clear();
  job.exit_code = *code;
  job.finished = Now();
  job.state = job.stop_requested > 0 ? JobState::kStopped : *code == 0 ? JobState::kDone : JobState::kFailed;
  for (auto& s : job.stages)
    if (s.state == StageState::kRunning)
      s.state = job.state == JobState::kStopped ? StageState::kStopped : StageState::kFailed;
  const nlohmann::json record = ToJson(job, false);
  try {
    core::WriteJson(fs::path(job.log_path).replace_extension(".json"), record);
  } catch (const Error&) {
    // The workspace went away or is read-only: the job is still reported for this server's life.
  }
  Publish("job", record);
}

void JobManager::Publish(const std::string& type, const nlohmann::json& data) {
  if (!replaying_) hub_->Publish(type, data);
}

std::unique_ptr<JobManager::Job> JobManager::RestoreJob(const std::string& workspace, const fs::path& log_path) {
  // ID-TIME.log: both parts decimal.
  const std::string stem = log_path.stem().string();
  const size_t dash = stem.find('-');
  const auto digits = [](const std::string& t) {
    return !t.empty() && t.size() <= 12 && t.find_first_not_of("0123456789") == std::string::npos;
  };
  if (dash == std::string::npos || !digits(stem.substr(0, dash)) || !digits(stem.substr(dash + 1))) return nullptr;
  auto job = std::make_unique<Job>();
  job->id = std::to_string(std::stoll(stem.substr(0, dash)));
  job->workspace = workspace;
  job->started = std::stod(stem.substr(dash + 1));
  job->log_path = log_path;
  job->progress_path = fs::path(log_path).replace_extension(".progress.jsonl");
  for (const auto& name : StageNames()) job->stages.push_back({name});
  for (const auto& line : ReadNewLines(job->progress_path, &job->progress_offset, &job->progress_partial))
    HandleProgressLine(*job, line);
  // The log's tail (ReadNewLines reads 4 MB at a time; the deque keeps the last log_lines).
  for (uint64_t before = ~0ull; before != job->log_offset;) {
    before = job->log_offset;
    for (const auto& line : ReadNewLines(job->log_path, &job->log_offset, &job->log_partial)) HandleLogLine(*job, line);
  }
  const fs::path record_path = fs::path(log_path).replace_extension(".json");
  const nlohmann::json record =
      fs::exists(record_path) ? nlohmann::json::parse(core::ReadTextFile(record_path), nullptr, false) : nullptr;
  std::error_code ec;
  const auto mtime = fs::last_write_time(log_path, ec);
  const double log_time =
      ec ? job->started : std::chrono::duration<double>(mtime - fs::file_time_type::clock::now()).count() + Now();
  if (record.is_object()) {
    // A job that had not ended when its record was written counts as stopped.
    const std::optional<JobState> state = ParseJobState(record.value("state", std::string()));
    job->state = state == JobState::kDone || state == JobState::kFailed ? *state : JobState::kStopped;
    if (record.contains("exit_code") && record["exit_code"].is_number_integer())
      job->exit_code = record["exit_code"].get<int>();
    job->finished =
        record.contains("finished") && record["finished"].is_number() ? record["finished"].get<double>() : log_time;
    if (record.contains("started") && record["started"].is_number()) job->started = record["started"].get<double>();
    if (record.contains("stage") && record["stage"].is_string()) job->stage = record["stage"].get<std::string>();
    if (record.contains("stages") && record["stages"].is_array()) {
      job->stages.clear();
      for (const auto& st : record["stages"])
        if (st.is_object() && st.contains("name") && st["name"].is_string())
          job->stages.push_back({st["name"].get<std::string>(),
                                 ParseStageState(st.value("state", std::string())).value_or(StageState::kPending),
                                 st.value("done", 0.0), st.value("total", 0.0), st.value("eta_s", 0.0)});
    }
  } else {
    job->state = JobState::kStopped;
    job->finished = std::max(log_time, job->started);
    HandleLogLine(*job, "(the server stopped while this job ran; its end was not recorded)");
  }
  for (auto& s : job->stages)
    if (s.state == StageState::kRunning)
      s.state = job->state == JobState::kFailed ? StageState::kFailed : StageState::kStopped;
  return job;
}

void JobManager::RestoreHistory(const std::vector<std::pair<std::string, fs::path>>& workspaces) {
  std::lock_guard<std::mutex> lock(mutex_);
  replaying_ = true;
  std::vector<std::unique_ptr<Job>> restored;
  for (const auto& [name, dir] : workspaces) {
    std::error_code ec;
    for (fs::directory_iterator it(dir / "jobs", ec), end; !ec && it != end; it.increment(ec)) {
      if (it->path().extension() != ".log" || !it->is_regular_file(ec)) continue;
      try {
        if (auto job = RestoreJob(name, it->path())) restored.push_back(std::move(job));
      } catch (const std::exception&) {
        // An unreadable or foreign file in jobs/ is not history.
      }
    }
  }
  replaying_ = false;
  std::sort(restored.begin(), restored.end(), [](const auto& a, const auto& b) {
    return std::stoll(a->id) != std::stoll(b->id) ? std::stoll(a->id) < std::stoll(b->id) : a->started < b->started;
  });
  for (auto& job : restored) {
    next_id_ = std::max<long long>(next_id_, std::stoll(job->id) + 1);
    jobs_.push_back(std::move(job));
  }
}

void JobManager::MonitorLoop() {
  while (!quit_) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (auto& j : jobs_)
        if (j->state == JobState::kRunning) Poll(*j);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

}  // namespace fmv3d::server
