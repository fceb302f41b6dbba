#include "fmv3d/server/server.h"

#include <unistd.h>

#include <fstream>
#include <utility>

#include "fmv3d/core/error.h"
#include "fmv3d/server/routes.h"
#include "fmv3d/server/validation.h"
#include "fmv3d/server/workspace_state.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

bool IsLoopbackHost(const std::string& host) { return host == "127.0.0.1" || host == "::1" || host == "localhost"; }

void ServerOptions::Check() const {
  std::error_code ec;
  if (!fs::is_directory(ws_root, ec)) throw Error(ws_root.string() + ": WS_ROOT is not a folder");
  if (!IsLoopbackHost(host) && token.empty())
    throw Error("--host " + host + " is reachable from other machines: it needs a token (--token-file)");
  if (port < 0 || port > 65535) throw Error("--port must be in [0, 65535]");
  if (threads < 2 || max_event_readers < 1 || max_event_readers >= threads)
    throw Error("server: threads must be >= 2 and above max_event_readers >= 1");
  if (max_upload_bytes == 0) throw Error("--max-upload-mb must be positive");
}

std::string RandomToken() {
  std::ifstream in("/dev/urandom", std::ios::binary);
  unsigned char bytes[32];
  if (!in.read(reinterpret_cast<char*>(bytes), sizeof(bytes))) throw Error("/dev/urandom: cannot read");
  static const char* hex = "0123456789abcdef";
  std::string t;
  for (unsigned char b : bytes) t += hex[b >> 4], t += hex[b & 15];
  return t;
}

fs::path SelfExecutable() {
  std::string exe = fs::read_symlink("/proc/self/exe").string();
  const std::string deleted = " (deleted)";
  if (exe.size() > deleted.size() && exe.compare(exe.size() - deleted.size(), deleted.size(), deleted) == 0)
    exe.resize(exe.size() - deleted.size());
  return exe;
}

std::string ReadTokenFile(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error(path.string() + ": cannot read the token file");
  std::string line;
  std::getline(in, line);
  while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
  while (!line.empty() && std::isspace(static_cast<unsigned char>(line.front()))) line.erase(line.begin());
  if (line.size() < 16) throw Error(path.string() + ": the token must be at least 16 characters");
  return line;
}

void SendJson(httplib::Response& res, int status, const nlohmann::json& body) {
  res.status = status;
  res.set_content(body.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace), "application/json");
}

void SendError(httplib::Response& res, int status, const std::string& message, const std::string& field) {
  nlohmann::json j = {{"error", message}};
  if (!field.empty()) j["field"] = field;
  SendJson(res, status, j);
}

void Guard(httplib::Response& res, const std::function<void()>& handler) {
  try {
    handler();
  } catch (const RequestError& e) {
    SendError(res, e.status(), e.what(), e.field());
  } catch (const std::exception& e) {
    SendError(res, 500, e.what());
  }
}

fs::path WorkspaceDir(const Context& ctx, const std::string& name) {
  if (!IsValidWorkspaceName(name))
    throw RequestError(400, "bad workspace name (one path component of [A-Za-z0-9._ -], not starting with '.')", "ws");
  const auto dir = ResolveInside(ctx.ws_root, name);
  std::error_code ec;
  if (!dir || !fs::is_directory(*dir, ec) || dir->parent_path() != ctx.ws_root)
    throw RequestError(404, "no workspace '" + name + "'");
  return *dir;
}

namespace {
std::string ContentType(const fs::path& p) {
  static const std::pair<const char*, const char*> types[] = {{".html", "text/html; charset=utf-8"},
                                                              {".js", "text/javascript"},
                                                              {".mjs", "text/javascript"},
                                                              {".css", "text/css"},
                                                              {".json", "application/json"},
                                                              {".map", "application/json"},
                                                              {".png", "image/png"},
                                                              {".jpg", "image/jpeg"},
                                                              {".jpeg", "image/jpeg"},
                                                              {".svg", "image/svg+xml"},
                                                              {".ico", "image/x-icon"},
                                                              {".webp", "image/webp"},
                                                              {".wasm", "application/wasm"},
                                                              {".woff2", "font/woff2"},
                                                              {".glb", "model/gltf-binary"},
                                                              {".tif", "image/tiff"},
                                                              {".tiff", "image/tiff"},
                                                              {".txt", "text/plain; charset=utf-8"},
                                                              {".log", "text/plain; charset=utf-8"},
                                                              {".jsonl", "text/plain; charset=utf-8"},
                                                              {".mtl", "text/plain; charset=utf-8"}};
  const std::string ext = p.extension().string();
  for (const auto& [e, t] : types)
    if (ext == e) return t;
  return "application/octet-stream";
}
}  // namespace

void SendFile(httplib::Response& res, const fs::path& path) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec || !fs::is_regular_file(path, ec)) throw RequestError(404, "no such file");
  auto file = std::make_shared<std::ifstream>(path, std::ios::binary);
  if (!*file) throw RequestError(404, "cannot open the file");
  res.set_header("Cache-Control", "no-cache");
  res.set_content_provider(static_cast<size_t>(size), ContentType(path),
                           [file](size_t offset, size_t length, httplib::DataSink& sink) {
                             std::vector<char> buf(std::min<size_t>(length, 1 << 16));
                             file->clear();
                             file->seekg(static_cast<std::streamoff>(offset));
                             file->read(buf.data(), static_cast<std::streamsize>(buf.size()));
                             const auto n = file->gcount();
                             return n > 0 && sink.write(buf.data(), static_cast<size_t>(n));
                           });
}

struct Server::Impl {
  Context ctx;
  EventHub hub;
  std::unique_ptr<JobManager> jobs;
  httplib::Server http;
  int port = 0;
};

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>()) {
  options.Check();
  if (options.executable.empty()) options.executable = SelfExecutable();
  Context& ctx = impl_->ctx;
  ctx.ws_root = fs::canonical(options.ws_root);
  std::error_code ec;
  if (!options.asset_dir.empty() && fs::is_directory(options.asset_dir, ec))
    ctx.asset_root = fs::canonical(options.asset_dir);
  ctx.options = options;
  ctx.hub = &impl_->hub;
  impl_->jobs = std::make_unique<JobManager>(JobManagerOptions{options.executable}, &impl_->hub);
  ctx.jobs = impl_->jobs.get();
  std::vector<std::pair<std::string, fs::path>> workspaces;
  for (const auto& name : ListWorkspaces(ctx.ws_root)) workspaces.emplace_back(name, ctx.ws_root / name);
  impl_->jobs->RestoreHistory(workspaces);

  httplib::Server& http = impl_->http;
  const int threads = options.threads;
  http.new_task_queue = [threads] { return new httplib::ThreadPool(static_cast<size_t>(threads)); };
  http.set_read_timeout(options.timeout_s, 0);
  http.set_write_timeout(options.timeout_s, 0);
  http.set_keep_alive_timeout(5);
  http.set_keep_alive_max_count(100);
  http.set_payload_max_length(options.max_upload_bytes);
  http.set_default_headers({{"X-Content-Type-Options", "nosniff"}, {"Referrer-Policy", "no-referrer"}});
  // Before any route: NUL bytes are refused everywhere; /api/ and /files/ need the token when one is set.
  http.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    if (req.path.find('\0') != std::string::npos) {
      SendError(res, 400, "NUL byte in the path");
      return httplib::Server::HandlerResponse::Handled;
    }
    const bool protected_path = req.path.rfind("/api/", 0) == 0 || req.path.rfind("/files/", 0) == 0;
    const std::string& token = impl_->ctx.options.token;
    if (!protected_path || token.empty()) return httplib::Server::HandlerResponse::Unhandled;
    std::string given;
    const std::string auth = req.get_header_value("Authorization");
    if (auth.rfind("Bearer ", 0) == 0)
      given = auth.substr(7);
    else if (req.has_param("token"))
      given = req.get_param_value("token");
    if (given.empty() || !ConstantTimeEquals(given, token)) {
      SendError(res, 401,
                given.empty() ? "this server needs a token (Authorization: Bearer T or ?token=T)" : "wrong token");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  http.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    try {
      std::rethrow_exception(std::move(ep));
    } catch (const std::exception& e) {
      SendError(res, 500, e.what());
    } catch (...) {
      SendError(res, 500, "internal error");
    }
  });
  RegisterManualRoutes(http, ctx);
  RegisterApiRoutes(http, ctx);
  RegisterFileRoutes(http, ctx);
}

Server::~Server() {
  Stop();
  impl_->jobs.reset();
}

int Server::Bind() {
  const auto& o = impl_->ctx.options;
  if (o.port == 0) {
    impl_->port = impl_->http.bind_to_any_port(o.host);
  } else {
    impl_->port = impl_->http.bind_to_port(o.host, o.port) ? o.port : -1;
  }
  if (impl_->port <= 0)
    throw Error("cannot listen on " + o.host + ":" + std::to_string(o.port) + " (in use, or not an address here)");
  return impl_->port;
}

void Server::Run() { impl_->http.listen_after_bind(); }

void Server::Stop() {
  impl_->hub.Close();
  impl_->http.stop();
}

std::string Server::Url() const {
  const auto& o = impl_->ctx.options;
  const std::string host = o.host.find(':') != std::string::npos ? "[" + o.host + "]" : o.host;
  std::string url = "http://" + host + ":" + std::to_string(impl_->port) + "/";
  if (!o.token.empty()) url += "?token=" + o.token;
  return url;
}

}  // namespace fmv3d::server
