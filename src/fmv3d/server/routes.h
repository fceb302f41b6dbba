// Internal to the server module: the state the request handlers share, and the route tables (api_routes.cc,
// file_routes.cc). Nothing outside src/fmv3d/server includes this.
#pragma once

#include <httplib.h>
#undef _res  // <resolv.h> (included by httplib.h) defines it; Eigen names a parameter _res

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "fmv3d/server/events.h"
#include "fmv3d/server/jobs.h"
#include "fmv3d/server/server.h"

namespace fmv3d::server {

struct Context {
  ServerOptions options;
  std::filesystem::path ws_root;     // canonical
  std::filesystem::path asset_root;  // canonical, or empty when the folder does not exist
  EventHub* hub = nullptr;
  JobManager* jobs = nullptr;
};

constexpr size_t kMaxJsonBody = 1 << 20;

void SendJson(httplib::Response& res, int status, const nlohmann::json& body);
void SendError(httplib::Response& res, int status, const std::string& message, const std::string& field = {});
// Runs `handler`, turning RequestError into its status, fmv3d::Error and other exceptions into 500 (JSON).
void Guard(httplib::Response& res, const std::function<void()>& handler);
// The workspace folder for a {ws} path segment: RequestError 400 for a bad name, 404 when it is not a folder
// under WS_ROOT (a symlink out of the root included).
std::filesystem::path WorkspaceDir(const Context& ctx, const std::string& name);
// Streams a file (HTTP ranges supported) with a content type from its extension.
void SendFile(httplib::Response& res, const std::filesystem::path& path);

void RegisterApiRoutes(httplib::Server& http, Context& ctx);
void RegisterFileRoutes(httplib::Server& http, Context& ctx);
// The hand tools' endpoints (manual_routes.cc); registered before the API's catch-all.
void RegisterManualRoutes(httplib::Server& http, Context& ctx);  // /files/{ws}/... and the front end's assets

}  // namespace fmv3d::server
