// `fmv3d serve [WS_ROOT]`: the operator console (src/fmv3d/server/server.h, docs/console-api.md).
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include "command.h"
#include "fmv3d/server/server.h"

namespace fmv3d::app::cmd_serve {
namespace {

std::atomic<server::Server*> g_server{nullptr};

void Add(CLI::App& app) {
  auto* cmd =
      app.add_subcommand("serve", "Serve the operator console (web page + HTTP API) for the workspaces in WS_ROOT");
  struct Args {
    std::string ws_root = ".", host = "127.0.0.1", token_file, assets;
    int port = 8080, max_upload_mb = 2048;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("WS_ROOT", a->ws_root, "Folder whose sub-folders are workspaces")->capture_default_str();
  cmd->add_option("--port", a->port, "TCP port")->capture_default_str()->check(CLI::Range(1, 65535));
  cmd->add_option("--host", a->host, "Address to bind; anything but loopback requires a token")->capture_default_str();
  cmd->add_option("--token-file", a->token_file, "File whose first line is the access token (else random)");
  cmd->add_option("--assets", a->assets, "The built front end (default: web/ beside the fmv3d binary)");
  cmd->add_option("--max-upload-mb", a->max_upload_mb, "Upload size limit")
      ->capture_default_str()
      ->check(CLI::Range(1, 1 << 20));
  cmd->callback([a] {
    server::ServerOptions o;
    o.ws_root = a->ws_root;
    o.host = a->host;
    o.port = a->port;
    o.max_upload_bytes = static_cast<size_t>(a->max_upload_mb) << 20;
    const std::filesystem::path exe = server::SelfExecutable();
    o.executable = exe;
    o.asset_dir = a->assets.empty() ? exe.parent_path() / "web" : std::filesystem::path(a->assets);
    if (!a->token_file.empty())
      o.token = server::ReadTokenFile(a->token_file);
    else if (!server::IsLoopbackHost(o.host))
      o.token = server::RandomToken();
    // SIGINT / SIGTERM are blocked in every thread (set before any is started) and taken by a watcher thread
    // that stops the server cleanly (running jobs get SIGTERM too); jobs reset the mask (server/process.h).
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
    server::Server srv(o);
    srv.Bind();
    g_server = &srv;
    std::thread watcher([set] {
      int sig = 0;
      sigwait(&set, &sig);
      if (server::Server* s = g_server.load()) s->Stop();
    });
    watcher.detach();
    if (!std::filesystem::is_regular_file(o.asset_dir / "index.html"))
      std::fprintf(stderr, "fmv3d serve: no built front end in %s (run `make web`, or give --assets DIR)\n",
                   o.asset_dir.c_str());
    std::printf("fmv3d console: open %s\n", srv.Url().c_str());
    std::fflush(stdout);
    srv.Run();
    g_server = nullptr;
  });
}

const RegisterCommand reg(1100, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_serve
