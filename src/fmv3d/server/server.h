// `fmv3d serve`: the operator console's HTTP server (docs/console-api.md is the contract): the built front end
// from the asset root, the JSON API, the event stream and the workspaces' files, from one process.
//
// Security: binds 127.0.0.1 by default; any other host needs a token, checked (constant time) on every /api/
// and /files/ request, as `Authorization: Bearer T` or `?token=T`. No CORS headers. Files come only from the
// asset root and the workspaces under WS_ROOT (validation.h: no "..", absolute paths, NUL bytes or symlinks out
// of the root). A bounded worker pool with read/write timeouts; request bodies are limited (uploads to
// max_upload_bytes, JSON to 1 MB) and validated.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

namespace fmv3d::server {

struct ServerOptions {
  std::filesystem::path ws_root = ".";
  std::filesystem::path asset_dir;  // the built web/ (may be missing: "/" then says how to build it)
  std::string host = "127.0.0.1";
  int port = 8080;    // 0: any free port (tests)
  std::string token;  // empty: none (loopback only)
  size_t max_upload_bytes = size_t{2048} << 20;
  std::filesystem::path executable;  // the fmv3d binary jobs run (default: this process's own, /proc/self/exe)
  int threads = 16;                  // worker pool
  int max_event_readers = 8;         // concurrent /api/events connections (each holds a worker)
  int timeout_s = 10;                // socket read and write timeouts
  // Throws fmv3d::Error: WS_ROOT not a folder, a non-loopback host without a token, bad numbers.
  void Check() const;
};

bool IsLoopbackHost(const std::string& host);
// 32 random bytes from /dev/urandom as 64 hex digits.
std::string RandomToken();
// This process's executable (/proc/self/exe), without the " (deleted)" Linux appends once the file was replaced
// (a rebuilt binary): jobs then run the new file at the same path.
std::filesystem::path SelfExecutable();
// The token in a token file: its first line, trimmed; throws fmv3d::Error when missing or shorter than 16.
std::string ReadTokenFile(const std::filesystem::path& path);

class Server {
 public:
  explicit Server(ServerOptions options);  // calls options.Check()
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;
  // Binds the socket; returns the port (the chosen one when options.port is 0). Throws fmv3d::Error.
  int Bind();
  // Serves until Stop() (blocking). Bind() first.
  void Run();
  void Stop();
  // "http://HOST:PORT/" (+ "?token=T" when a token is set).
  std::string Url() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fmv3d::server
