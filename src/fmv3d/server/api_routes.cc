// The JSON API and the event stream (docs/console-api.md, "Endpoints" and "Events").
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/server/geo_json.h"
#include "fmv3d/server/model_json.h"
#include "fmv3d/server/routes.h"
#include "fmv3d/server/validation.h"
#include "fmv3d/server/workspace_state.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

namespace {

nlohmann::json WorkspaceJson(const Context& ctx, const fs::path& dir) {
  const std::string name = dir.filename().string();
  nlohmann::json w = DescribeWorkspace(dir, ctx.jobs->StageOverrides(name));
  w["job"] = ctx.jobs->LatestFor(name);
  return w;
}

void RequireJsonBody(const httplib::Request& req) {
  if (req.body.size() > kMaxJsonBody) throw RequestError(413, "the JSON body is larger than 1 MB", "body");
}

// A job input: relative paths inside the workspace first, then inside WS_ROOT; absolute paths must lie in WS_ROOT.
fs::path ResolveInput(const Context& ctx, const fs::path& ws_dir, const std::string& in) {
  std::error_code ec;
  if (!in.empty() && in.front() == '/') {
    fs::path p = fs::weakly_canonical(fs::path(in), ec);
    if (!ec && IsWithin(ctx.ws_root, p) && fs::exists(p, ec)) return p;
    throw RequestError(400, "'inputs': " + in + " is not an existing path under WS_ROOT", "inputs");
  }
  for (const fs::path& root : {ws_dir, ctx.ws_root}) {
    const auto p = ResolveInside(root, in);
    if (!p && p.refusal != PathRefusal::kLeavesRoot && p.refusal != PathRefusal::kUnresolvable)
      throw RequestError(400, "'inputs': " + in + ": " + p.why(), "inputs");
    if (p && fs::exists(*p, ec)) return *p;
  }
  throw RequestError(400, "'inputs': " + in + " is not in the workspace nor under WS_ROOT", "inputs");
}

void HandleUpload(Context& ctx, const httplib::Request& req, httplib::Response& res,
                  const httplib::ContentReader& reader) {
  const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
  if (!req.is_multipart_form_data()) throw RequestError(400, "uploads are multipart/form-data", "file");
  const fs::path uploads = dir / "uploads";
  core::EnsureDirectory(uploads);
  std::vector<fs::path> done_paths, partial;
  std::ofstream out;
  fs::path current, current_final;
  std::string bad;
  auto finish_current = [&] {
    if (current.empty()) return;
    out.close();
    fs::rename(current, current_final);
    done_paths.push_back(current_final);
    partial.pop_back();
    current.clear();
  };
  const bool ok = reader(
      [&](const httplib::MultipartFormData& field) {
        finish_current();
        if (field.name != "file") {
          bad = "unexpected form field '" + field.name + "' (uploads use the field 'file')";
          return false;
        }
        std::string name;
        try {
          name = SanitiseUploadName(field.filename);
        } catch (const RequestError& e) {
          bad = e.what();
          return false;
        }
        fs::path target = uploads / name;
        std::error_code ec;
        for (int k = 1; fs::exists(target, ec); ++k)
          target = uploads /
                   (fs::path(name).stem().string() + "-" + std::to_string(k) + fs::path(name).extension().string());
        current_final = target;
        current = fs::path(target).concat(".part");
        partial.push_back(current);
        out.open(current, std::ios::binary | std::ios::trunc);
        return static_cast<bool>(out);
      },
      [&](const char* data, size_t n) {
        if (current.empty()) return false;
        out.write(data, static_cast<std::streamsize>(n));
        return static_cast<bool>(out);
      });
  if (ok && bad.empty()) finish_current();
  if (!ok || !bad.empty()) {
    out.close();
    std::error_code ec;
    for (const auto& p : partial) fs::remove(p, ec);
    if (!bad.empty()) throw RequestError(400, bad, "file");
    // httplib stops reading at the payload limit and has set 413.
    if (res.status == 413) throw RequestError(413, "the upload exceeds --max-upload-mb", "file");
    throw RequestError(400, "the upload could not be read", "file");
  }
  if (done_paths.empty()) throw RequestError(400, "no file in the upload (field 'file')", "file");
  nlohmann::json paths = nlohmann::json::array();
  for (const auto& p : done_paths) paths.push_back("uploads/" + p.filename().string());
  SendJson(res, 201, {{"paths", paths}});
}

// One SSE connection: a snapshot, then every event as it comes, a comment every 15 s to notice a closed peer.
void HandleEvents(Context& ctx, const httplib::Request&, httplib::Response& res) {
  if (!ctx.hub->TryAddReader(ctx.options.max_event_readers))
    throw RequestError(503, "too many event streams open (close another console tab)");
  auto last = std::make_shared<uint64_t>(ctx.hub->LastSeq());
  auto snapshot = std::make_shared<std::string>(FormatSse({0, "snapshot", ctx.jobs->List().dump()}));
  res.set_header("Cache-Control", "no-cache");
  res.set_header("X-Accel-Buffering", "no");
  EventHub* hub = ctx.hub;
  res.set_chunked_content_provider(
      "text/event-stream",
      [hub, last, snapshot](size_t, httplib::DataSink& sink) {
        if (!snapshot->empty()) {
          const std::string s = std::move(*snapshot);
          snapshot->clear();
          return sink.write(s.data(), s.size());
        }
        const auto events = hub->WaitAfter(*last, std::chrono::seconds(15));
        if (hub->closed()) {
          sink.done();
          return true;
        }
        std::string text;
        for (const auto& e : events) text += FormatSse(e), *last = e.seq;
        if (text.empty()) text = ": keep-alive\n\n";
        return sink.write(text.data(), text.size());
      },
      [hub](bool) { hub->RemoveReader(); });
}

}  // namespace

void RegisterApiRoutes(httplib::Server& http, Context& ctx) {
  http.Get("/api/health", [&ctx](const httplib::Request&, httplib::Response& res) {
    SendJson(res, 200,
             {{"version", FMV3D_VERSION},
              {"ws_root", ctx.ws_root.string()},
              {"token_required", !ctx.options.token.empty()}});
  });
  http.Get("/api/workspaces", [&ctx](const httplib::Request&, httplib::Response& res) {
    Guard(res, [&] {
      nlohmann::json out = nlohmann::json::array();
      for (const auto& name : ListWorkspaces(ctx.ws_root)) out.push_back(WorkspaceJson(ctx, ctx.ws_root / name));
      SendJson(res, 200, out);
    });
  });
  http.Post("/api/workspaces", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      RequireJsonBody(req);
      const std::string name = ParseCreateWorkspace(req.body);
      const fs::path dir = ctx.ws_root / name;
      std::error_code ec;
      if (fs::exists(dir, ec) || fs::is_symlink(dir, ec))
        throw RequestError(409, "'" + name + "' already exists", "name");
      core::EnsureDirectory(dir);
      core::WriteJson(dir / "project.json", {{"fmv3d_version", FMV3D_VERSION}, {"inputs", nlohmann::json::array()}});
      SendJson(res, 201, {{"name", name}});
    });
  });
  http.Get(R"(/api/workspaces/([^/]+))", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      nlohmann::json w = WorkspaceJson(ctx, dir);
      w["files"] = WorkspaceFiles(dir);
      SendJson(res, 200, w);
    });
  });
  http.Post(R"(/api/workspaces/([^/]+)/uploads)",
            [&ctx](const httplib::Request& req, httplib::Response& res, const httplib::ContentReader& reader) {
              Guard(res, [&] { HandleUpload(ctx, req, res, reader); });
            });
  http.Post(R"(/api/workspaces/([^/]+)/jobs)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      RequireJsonBody(req);
      const JobRequest r = ParseJobRequest(req.body);
      ctx.jobs->RequireIdle(dir.filename().string());
      std::vector<fs::path> inputs;
      for (const auto& in : r.inputs) inputs.push_back(ResolveInput(ctx, dir, in));
      if (inputs.empty())
        for (const auto& in : ProjectInputs(dir)) inputs.emplace_back(in);
      if (inputs.empty())
        throw RequestError(400, "'inputs': none given and the workspace's project.json records none", "inputs");
      SendJson(res, 202, ctx.jobs->Start(dir.filename().string(), dir, inputs, r));
    });
  });
  http.Get("/api/jobs",
           [&ctx](const httplib::Request&, httplib::Response& res) { SendJson(res, 200, ctx.jobs->List()); });
  http.Get(R"(/api/jobs/([^/]+))", [&ctx](const httplib::Request& req, httplib::Response& res) {
    const auto job = ctx.jobs->Get(req.matches[1], true);
    if (!job) return SendError(res, 404, "no job '" + std::string(req.matches[1]) + "'");
    SendJson(res, 200, *job);
  });
  http.Post(R"(/api/jobs/([^/]+)/stop)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    const auto job = ctx.jobs->Stop(req.matches[1]);
    if (!job) return SendError(res, 404, "no job '" + std::string(req.matches[1]) + "'");
    SendJson(res, 200, *job);
  });
  http.Get("/api/events", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] { HandleEvents(ctx, req, res); });
  });
  http.Get(R"(/api/workspaces/([^/]+)/cameras)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const core::Workspace ws(WorkspaceDir(ctx, req.matches[1]));
      if (!fs::exists(ws.sparse_dir() / "images.txt")) throw RequestError(404, "no sparse model yet");
      SendJson(res, 200, CamerasJson(io::ReadColmapText(ws.sparse_dir())));
    });
  });
  http.Get(R"(/api/workspaces/([^/]+)/sparse)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const core::Workspace ws(WorkspaceDir(ctx, req.matches[1]));
      if (!fs::exists(ws.sparse_dir() / "images.txt")) throw RequestError(404, "no sparse model yet");
      SendJson(res, 200, SparseJson(io::ReadColmapText(ws.sparse_dir())));
    });
  });
  http.Get(R"(/api/workspaces/([^/]+)/report)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path report = core::Workspace(WorkspaceDir(ctx, req.matches[1])).report_dir() / "report.json";
      if (!fs::exists(report)) throw RequestError(404, "no report yet");
      SendJson(res, 200, core::ReadJson(report));
    });
  });
  http.Get(R"(/api/workspaces/([^/]+)/geo)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const nlohmann::json g = GeoJson(WorkspaceDir(ctx, req.matches[1]));
      if (g.is_null()) throw RequestError(404, "the workspace is not georeferenced (no geo/georef.json)");
      SendJson(res, 200, g);
    });
  });
  http.Get(R"(/api/workspaces/([^/]+)/profile)", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (!req.has_param("from")) throw RequestError(400, "'from' is required (LAT,LON)", "from");
      if (!req.has_param("to")) throw RequestError(400, "'to' is required (LAT,LON)", "to");
      const LatLon from = ParseLatLon(req.get_param_value("from"), "from");
      const LatLon to = ParseLatLon(req.get_param_value("to"), "to");
      const int n = req.has_param("n") ? ParseBoundedInt(req.get_param_value("n"), 2, 5000, "n") : 200;
      if (!fs::exists(dir / "geo" / "dsm.tif")) throw RequestError(404, "no geo/dsm.tif in this workspace");
      SendJson(res, 200, ProfileJson(dir, from, to, n));
    });
  });
  // Unknown API paths answer JSON, not the front end's page.
  http.Get(R"(/api/.*)",
           [](const httplib::Request&, httplib::Response& res) { SendError(res, 404, "no such endpoint"); });
}

}  // namespace fmv3d::server
