// A server started in-process on an ephemeral loopback port over a WS_ROOT made at test time: "ws1" built from
// files (frames index with telemetry, a COLMAP model, report, georef, DSM, a few plain files) plus the traps the
// security tests need (a symlink out of the workspace, a workspace symlinked from outside, a hidden folder).
#pragma once

#include <httplib.h>
#undef _res  // <resolv.h> (included by httplib.h) defines it; Eigen names a parameter _res

#include <gtest/gtest.h>

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "fmv3d/server/server.h"
#include "test_util.h"

namespace fmv3d::server::test {

struct RunningServer {
  explicit RunningServer(ServerOptions options);
  ~RunningServer();
  std::unique_ptr<httplib::Client> Client() const;  // url-encoding off: paths go out exactly as written
  int port = 0;
  std::unique_ptr<Server> server;
  std::thread thread;
};

// Writes the workspace described above into root/ws1 (+ root/evil, root/.hidden, outside/).
void MakeWorkspaceRoot(const std::filesystem::path& tmp);

inline nlohmann::json Json(const httplib::Result& r) {
  if (!r) return nullptr;
  return nlohmann::json::parse(r->body, nullptr, false);
}

}  // namespace fmv3d::server::test
