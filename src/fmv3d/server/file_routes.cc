// Files: /files/{ws}/{path} from the workspaces under WS_ROOT, and every other GET from the front end's asset
// root ("/" is its index.html). Paths are checked by ResolveInside (validation.h) after httplib has decoded them,
// so "%2e%2e" is refused as "..".
#include "fmv3d/server/routes.h"
#include "fmv3d/server/validation.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

namespace {
const char* kNoAssetsPage = R"(<!doctype html><html><head><meta charset="utf-8"><title>fmv3d console</title></head>
<body style="font-family: sans-serif; max-width: 40em; margin: 3em auto">
<h1>fmv3d console: the web page is not built</h1>
<p>The server runs (its API answers at <code>/api/health</code>), but it found no built front end at
<code>%s</code>.</p>
<p>Build it once with <code>make web</code> (Node.js and npm; it writes <code>build/web/</code> beside the
<code>fmv3d</code> binary), or point the server at a built copy with <code>fmv3d serve --assets DIR</code>.</p>
</body></html>
)";

std::string NoAssetsPage(const Context& ctx) {
  std::string where = ctx.options.asset_dir.empty() ? std::string("(none given)") : ctx.options.asset_dir.string();
  std::string escaped;
  for (char c : where) {
    if (c == '<')
      escaped += "&lt;";
    else if (c == '>')
      escaped += "&gt;";
    else if (c == '&')
      escaped += "&amp;";
    else
      escaped += c;
  }
  std::string page = kNoAssetsPage;
  page.replace(page.find("%s"), 2, escaped);
  return page;
}
// httplib 0.11 sends a range's requested length even when it runs past the end of the file (the body then falls
// short of Content-Length); RFC 9110 says such a range ends at the last byte. COG readers ask for whole blocks.
void ClampRanges(const httplib::Request& req, const fs::path& path) {
  std::error_code ec;
  const auto size = static_cast<ssize_t>(fs::file_size(path, ec));
  if (ec || size <= 0) return;
  for (auto& r : const_cast<httplib::Request&>(req).ranges)
    if (r.second >= size) r.second = size - 1;
}
// A path outside its root is forbidden (403); a malformed one is a bad request.
RequestError PathRefused(const ResolvedPath& path) {
  return {path.refusal == PathRefusal::kLeavesRoot ? 403 : 400, std::string("refused: ") + path.why(), "path"};
}
}  // namespace

void RegisterFileRoutes(httplib::Server& http, Context& ctx) {
  http.Get(R"(/files/([^/]*)/(.*))", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      const auto path = ResolveInside(dir, std::string(req.matches[2]));
      if (!path) throw PathRefused(path);
      ClampRanges(req, *path);
      SendFile(res, *path);
    });
  });
  http.Get(R"(/files(/.*)?)", [](const httplib::Request&, httplib::Response& res) {
    SendError(res, 400, "use /files/{workspace}/{path}", "path");
  });
  http.Get(R"(/.*)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const bool index = req.path == "/" || req.path == "/index.html";
      if (ctx.asset_root.empty() || (index && !fs::is_regular_file(ctx.asset_root / "index.html"))) {
        res.status = index ? 503 : 404;
        res.set_content(NoAssetsPage(ctx), "text/html; charset=utf-8");
        return;
      }
      const auto path = ResolveInside(ctx.asset_root, index ? std::string("index.html") : req.path.substr(1));
      if (!path) throw PathRefused(path);
      ClampRanges(req, *path);
      SendFile(res, *path);
    });
  });
}

}  // namespace fmv3d::server
