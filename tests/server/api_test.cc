// The console's HTTP API (docs/console-api.md) against a server in-process: every read endpoint, creation,
// uploads, files with ranges, the security rules (traversal in every spelling, symlinks out of the root, NUL
// bytes, absolute paths, bad bodies, oversize uploads, no CORS) and the token rules.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <fstream>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "server_fixture.h"

namespace fmv3d::server::test {
namespace {

namespace fs = std::filesystem;

class Api : public ::testing::Test {
 protected:
  void SetUp() override {
    MakeWorkspaceRoot(tmp_.path());
    fs::create_directories(tmp_ / "assets");
    std::ofstream(tmp_ / "assets" / "index.html") << "<html>console</html>";
    std::ofstream(tmp_ / "assets" / "app.js") << "console.log(1)";
    ServerOptions o;
    o.ws_root = tmp_ / "root";
    o.asset_dir = tmp_ / "assets";
    o.executable = FMV3D_CLI;
    o.max_upload_bytes = 64 << 10;
    server_ = std::make_unique<RunningServer>(o);
    client_ = server_->Client();
  }
  fmv3d::test::TempDir tmp_{"api"};
  std::unique_ptr<RunningServer> server_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(Api, HealthAndWorkspaces) {
  auto r = client_->Get("/api/health");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(Json(r)["version"], FMV3D_VERSION);
  EXPECT_EQ(Json(r)["ws_root"], fs::canonical(tmp_ / "root").string());

  r = client_->Get("/api/workspaces");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const auto list = Json(r);
  ASSERT_EQ(list.size(), 1u) << list.dump();  // not the symlinked "evil", not ".hidden"
  const auto& w = list[0];
  EXPECT_EQ(w["name"], "ws1");
  EXPECT_EQ(w["frames"], 2);
  EXPECT_EQ(w["registered"], 2);
  EXPECT_TRUE(w["georeferenced"].get<bool>());
  EXPECT_TRUE(w["job"].is_null());
  std::map<std::string, std::string> states;
  for (const auto& s : w["stages"]) states[s["name"]] = s["state"];
  EXPECT_EQ(states.size(), 12u);
  EXPECT_EQ(states["frames"], "done");
  EXPECT_EQ(states["sparse"], "done");
  EXPECT_EQ(states["dense"], "pending");
  EXPECT_EQ(states["tiles"], "pending");
  EXPECT_EQ(states["report"], "done");

  r = client_->Get("/api/workspaces/ws1");
  ASSERT_EQ(r->status, 200);
  const auto one = Json(r);
  EXPECT_EQ(one["files"]["dsm"], "geo/dsm.tif");
  EXPECT_TRUE(one["files"]["fused_ply"].is_null());
  EXPECT_TRUE(one["files"]["tileset"].is_null());
  EXPECT_TRUE(one["files"]["cad_error"].is_null());
  // A CAD comparison written into the workspace is listed with its coloured CAD.
  std::filesystem::create_directories(tmp_ / "root" / "ws1" / "report" / "compare");
  core::WriteTextFile(tmp_ / "root" / "ws1" / "report" / "compare" / "compare.json", "{}");
  core::WriteTextFile(tmp_ / "root" / "ws1" / "report" / "compare" / "cad_error.ply", "ply\n");
  const auto again = Json(client_->Get("/api/workspaces/ws1"));
  EXPECT_EQ(again["files"]["compare"], "report/compare/compare.json");
  EXPECT_EQ(again["files"]["cad_error"], "report/compare/cad_error.ply");
  EXPECT_EQ(client_->Get("/api/workspaces/nope")->status, 404);
  EXPECT_EQ(client_->Get("/api/workspaces/evil")->status, 404);
  EXPECT_EQ(client_->Get("/api/workspaces/.hidden")->status, 400);
  EXPECT_EQ(client_->Get("/api/nothing-here")->status, 404);
}

TEST_F(Api, CreateWorkspace) {
  auto r = client_->Post("/api/workspaces", R"({"name": "flight 2"})", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 201);
  EXPECT_EQ(Json(r)["name"], "flight 2");
  EXPECT_TRUE(fs::is_directory(tmp_ / "root" / "flight 2"));
  EXPECT_EQ(Json(client_->Get("/api/workspaces")).size(), 2u);
  EXPECT_EQ(client_->Post("/api/workspaces", R"({"name": "flight 2"})", "application/json")->status, 409);
  EXPECT_EQ(client_->Post("/api/workspaces", R"({"name": "evil"})", "application/json")->status, 409);
  struct Bad {
    const char* body;
    const char* field;
  };
  for (const Bad& b : {Bad{R"({"name": "../up"})", "name"}, Bad{R"({"name": 5})", "name"}, Bad{R"({})", "name"},
                       Bad{R"({"name": "a/b"})", "name"}, Bad{"{not json", "body"}, Bad{"[1]", "body"}}) {
    r = client_->Post("/api/workspaces", b.body, "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << b.body;
    EXPECT_EQ(Json(r)["field"], b.field) << b.body;
    EXPECT_FALSE(Json(r)["error"].get<std::string>().empty());
  }
  EXPECT_FALSE(fs::exists(tmp_ / "up"));
  EXPECT_EQ(client_->Post("/api/workspaces", std::string(2 << 20, ' '), "application/json")->status, 413);
}

TEST_F(Api, CamerasSparseReport) {
  auto r = client_->Get("/api/workspaces/ws1/cameras");
  ASSERT_EQ(r->status, 200);
  const auto cams = Json(r);
  ASSERT_EQ(cams.size(), 2u);
  EXPECT_EQ(cams[0]["name"], "f1.png");
  EXPECT_EQ(cams[0]["frame"], "frames/f1.png");
  EXPECT_EQ(cams[0]["width"], 320);
  EXPECT_DOUBLE_EQ(cams[0]["fx"].get<double>(), 300);
  EXPECT_NEAR(cams[0]["center"][0].get<double>(), 2, 1e-9);
  EXPECT_NEAR(cams[0]["center"][2].get<double>(), 10, 1e-9);
  EXPECT_NEAR(cams[1]["reprojection_rms_px"].get<double>(), 0.5, 1e-6);
  EXPECT_EQ(cams[0]["rotation"].size(), 4u);

  r = client_->Get("/api/workspaces/ws1/sparse");
  ASSERT_EQ(r->status, 200);
  const auto sp = Json(r);
  EXPECT_EQ(sp["count"], 5);
  EXPECT_EQ(sp["positions"].size(), 15u);
  EXPECT_EQ(sp["colors"].size(), 15u);
  EXPECT_EQ(sp["colors"][12], 50);
  EXPECT_NEAR(sp["errors"][4].get<double>(), 0.5, 1e-6);

  r = client_->Get("/api/workspaces/ws1/report");
  ASSERT_EQ(r->status, 200);
  EXPECT_TRUE(Json(r)["test"].get<bool>());
  client_->Post("/api/workspaces", R"({"name": "empty"})", "application/json");
  for (const char* ep : {"cameras", "sparse", "report", "geo"})
    EXPECT_EQ(client_->Get(std::string("/api/workspaces/empty/") + ep)->status, 404) << ep;
}

TEST_F(Api, GeoAndProfile) {
  auto r = client_->Get("/api/workspaces/ws1/geo");
  ASSERT_EQ(r->status, 200);
  const auto g = Json(r);
  EXPECT_EQ(g["epsg"], 32632);
  EXPECT_DOUBLE_EQ(g["origin"]["lat"].get<double>(), 47.0);
  EXPECT_EQ(g["dsm"], "geo/dsm.tif");
  EXPECT_TRUE(g["ortho"].is_null());
  const auto& b = g["bounds_wgs84"];
  ASSERT_EQ(b.size(), 4u);
  EXPECT_LT(b[0].get<double>(), 8.0);
  EXPECT_GT(b[2].get<double>(), 8.0);
  EXPECT_LT(b[1].get<double>(), 47.0);
  EXPECT_GT(b[3].get<double>(), 47.0);
  EXPECT_EQ(g["track"].size(), 2u);
  ASSERT_EQ(g["footprints"].size(), 2u);
  // Camera 1 at ENU (2, 0, 10) looks straight down on ground at ~500 m (ENU z ~0): footprint centred below it.
  double lat = 0, lon = 0;
  for (const auto& c : g["footprints"][0]) lat += c[0].get<double>() / 4, lon += c[1].get<double>() / 4;
  EXPECT_NEAR(lat, 47.0, 2e-5);
  EXPECT_NEAR((lon - 8.0) * 111320 * std::cos(47.0 * M_PI / 180), 2.0, 0.5);

  // West → east across the DSM: heights rise 1 m per 10 m.
  r = client_->Get("/api/workspaces/ws1/profile?from=47.0,7.99985&to=47.0,8.00015&n=11");
  ASSERT_EQ(r->status, 200) << r->body;
  const auto pts = Json(r)["points"];
  ASSERT_EQ(pts.size(), 11u);
  const double length = pts[10]["distance_m"].get<double>();
  EXPECT_NEAR(length, 0.0003 * 111320 * std::cos(47.0 * M_PI / 180), 0.5);
  ASSERT_TRUE(pts[1]["height_m"].is_number() && pts[9]["height_m"].is_number());
  const double slope = (pts[9]["height_m"].get<double>() - pts[1]["height_m"].get<double>()) /
                       (pts[9]["distance_m"].get<double>() - pts[1]["distance_m"].get<double>());
  EXPECT_NEAR(slope, 0.1, 0.01);
  // Far outside the DSM: no height.
  r = client_->Get("/api/workspaces/ws1/profile?from=47.1,8.1&to=47.1,8.2&n=3");
  EXPECT_TRUE(Json(r)["points"][0]["height_m"].is_null());

  struct Bad {
    const char* query;
    const char* field;
  };
  for (const Bad& q : {Bad{"to=47,8", "from"}, Bad{"from=47,8", "to"}, Bad{"from=abc&to=47,8", "from"},
                       Bad{"from=47,8&to=95,8", "to"}, Bad{"from=47,8&to=47,8.1&n=1", "n"},
                       Bad{"from=47,8&to=47,8.1&n=x", "n"}, Bad{"from=47,8&to=47,8.1&n=99999", "n"}}) {
    r = client_->Get(std::string("/api/workspaces/ws1/profile?") + q.query);
    EXPECT_EQ(r->status, 400) << q.query;
    EXPECT_EQ(Json(r)["field"], q.field) << q.query;
  }
}

TEST_F(Api, FilesAndRanges) {
  auto r = client_->Get("/files/ws1/frames/f1.png");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_EQ(r->body, "PNG-ish bytes 1");
  EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
  r = client_->Get("/files/ws1/report/bytes.bin", {{"Range", "bytes=2-5"}});
  EXPECT_EQ(r->status, 206);
  EXPECT_EQ(r->body, "2345");
  r = client_->Get("/files/ws1/report/bytes.bin", {{"Range", "bytes=16-"}});
  EXPECT_EQ(r->status, 206);
  EXPECT_EQ(r->body, "ghij");
  EXPECT_EQ(client_->Get("/files/ws1/report/missing.bin")->status, 404);
  EXPECT_EQ(client_->Get("/files/ws1/frames")->status, 404);  // a folder is not a file
  EXPECT_EQ(client_->Get("/files/nope/x")->status, 404);
}

TEST_F(Api, TraversalSymlinksNulAndAbsolutePathsAreRefused) {
  for (const char* path : {"/files/ws1/../../outside/secret.txt",
                           "/files/ws1/%2e%2e/%2e%2e/outside/secret.txt",
                           "/files/ws1/%2E%2E/%2E%2E/outside/secret.txt",
                           "/files/ws1/..%2f..%2foutside%2fsecret.txt",
                           "/files/ws1/frames/%2e%2e/%2e%2e/%2e%2e/outside/secret.txt",
                           "/files/ws1/escape/secret.txt",
                           "/files/evil/secret.txt",
                           "/files/%2e%2e/outside/secret.txt",
                           "/files/..%2Foutside/secret.txt",
                           "/files/ws1//etc/passwd",
                           "/files/ws1/%2fetc%2fpasswd",
                           "/files/ws1/frames/f1.png%00.txt",
                           "/files/ws1%00/frames/f1.png",
                           "/files/.hidden/project.json",
                           "/files/ws1/..%5c..%5coutside%5csecret.txt",
                           "/%2e%2e/outside/secret.txt",
                           "/../outside/secret.txt",
                           "/..%2f..%2foutside/secret.txt",
                           "/app.js%00.html",
                           "/api/workspaces/..%2foutside"}) {
    const auto r = client_->Get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_GE(r->status, 400) << path;
    EXPECT_LT(r->status, 500) << path;
    EXPECT_EQ(r->body.find("secret"), std::string::npos) << path;
    EXPECT_EQ(r->body.find("root:"), std::string::npos) << path;
  }
}

TEST_F(Api, AssetsAndNoCors) {
  auto r = client_->Get("/", {{"Origin", "http://evil.example"}});
  ASSERT_EQ(r->status, 200);
  EXPECT_EQ(r->body, "<html>console</html>");
  EXPECT_FALSE(r->has_header("Access-Control-Allow-Origin"));
  EXPECT_EQ(client_->Get("/app.js")->body, "console.log(1)");
  EXPECT_EQ(client_->Get("/app.js")->get_header_value("Content-Type"), "text/javascript");
  EXPECT_EQ(client_->Get("/missing.js")->status, 404);
  r = client_->Get("/api/workspaces", {{"Origin", "http://evil.example"}});
  EXPECT_FALSE(r->has_header("Access-Control-Allow-Origin"));
  r = client_->Options("/api/workspaces",
                       {{"Origin", "http://evil.example"}, {"Access-Control-Request-Method", "POST"}});
  ASSERT_TRUE(r);
  EXPECT_FALSE(r->has_header("Access-Control-Allow-Origin"));
  EXPECT_FALSE(r->has_header("Access-Control-Allow-Methods"));
}

TEST_F(Api, StalledClientsDoNotBlockOthers) {
  // Four clients that send half a request line and stall; each holds one worker until the read timeout.
  std::vector<int> sockets;
  for (int i = 0; i < 4; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(server_->port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    const char partial[] = "GET /api/health HT";
    ASSERT_GT(::send(fd, partial, sizeof(partial) - 1, 0), 0);
    sockets.push_back(fd);
  }
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 10; ++i) {
    auto c = server_->Client();
    const auto r = c->Get("/api/health");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  for (int fd : sockets) ::close(fd);
}

TEST(ApiAssets, MissingAssetsGiveAClearPage) {
  fmv3d::test::TempDir tmp("api-noassets");
  MakeWorkspaceRoot(tmp.path());
  ServerOptions o;
  o.ws_root = tmp / "root";
  o.asset_dir = tmp / "no-such-folder";
  RunningServer s(o);
  auto r = s.Client()->Get("/");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_NE(r->body.find("make web"), std::string::npos);
  EXPECT_NE(r->body.find("no-such-folder"), std::string::npos);
  EXPECT_EQ(s.Client()->Get("/api/health")->status, 200);
}

TEST_F(Api, Uploads) {
  httplib::MultipartFormDataItems items = {{"file", "video bytes", "clip.mp4", "video/mp4"}};
  auto r = client_->Post("/api/workspaces/ws1/uploads", items);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 201) << r->body;
  EXPECT_EQ(Json(r)["paths"], nlohmann::json({"uploads/clip.mp4"}));
  EXPECT_EQ(core::ReadTextFile(tmp_ / "root" / "ws1" / "uploads" / "clip.mp4"), "video bytes");
  // Same name again, two files at once, a name that tries to climb out.
  items = {{"file", "again", "clip.mp4", "video/mp4"}, {"file", "x", "../../../evil.sh", "text/plain"}};
  r = client_->Post("/api/workspaces/ws1/uploads", items);
  ASSERT_EQ(r->status, 201) << r->body;
  EXPECT_EQ(Json(r)["paths"], nlohmann::json({"uploads/clip-1.mp4", "uploads/evil.sh"}));
  EXPECT_FALSE(fs::exists(tmp_ / "evil.sh"));
  EXPECT_TRUE(fs::exists(tmp_ / "root" / "ws1" / "uploads" / "evil.sh"));
  // Over the limit (64 KB here): 413, nothing left behind.
  items = {{"file", std::string(200 << 10, 'x'), "big.mp4", "video/mp4"}};
  r = client_->Post("/api/workspaces/ws1/uploads", items);
  if (r) {
    EXPECT_EQ(r->status, 413);  // the server may also close the connection while the client still sends
  }
  EXPECT_FALSE(fs::exists(tmp_ / "root" / "ws1" / "uploads" / "big.mp4"));
  EXPECT_FALSE(fs::exists(tmp_ / "root" / "ws1" / "uploads" / "big.mp4.part"));
  r = client_->Post("/api/workspaces/ws1/uploads", "raw", "application/octet-stream");
  EXPECT_EQ(r->status, 400);
  EXPECT_EQ(Json(r)["field"], "file");
  items = {{"other", "x", "a.mp4", "video/mp4"}};
  EXPECT_EQ(client_->Post("/api/workspaces/ws1/uploads", items)->status, 400);
  items = {{"file", "x", "..", "video/mp4"}};
  EXPECT_EQ(client_->Post("/api/workspaces/ws1/uploads", items)->status, 400);
  items = {{"file", "x", "a.mp4", "video/mp4"}};
  EXPECT_EQ(client_->Post("/api/workspaces/nope/uploads", items)->status, 404);
  EXPECT_EQ(client_->Post("/api/workspaces/evil/uploads", items)->status, 404);
  EXPECT_FALSE(fs::exists(tmp_ / "outside" / "uploads"));
}

TEST_F(Api, JobRequestsAreValidated) {
  struct Bad {
    const char* body;
    const char* field;
  };
  std::ofstream(tmp_ / "root" / "elsewhere.mp4") << "x";
  for (const Bad& b :
       {Bad{R"({"inputs": ["../../outside/secret.txt"]})", "inputs"}, Bad{R"({"inputs": ["/etc/passwd"]})", "inputs"},
        Bad{R"({"inputs": ["missing.mp4"]})", "inputs"}, Bad{R"({"inputs": ["escape/secret.txt"]})", "inputs"},
        Bad{R"({"inputs": "a.mp4"})", "inputs"}, Bad{R"({"inputs": [3]})", "inputs"}, Bad{R"({"fast": "yes"})", "fast"},
        Bad{R"({"from": "nowhere"})", "from"}, Bad{R"({"argv": ["sh"]})", "argv"}, Bad{"{]", "body"},
        Bad{R"({})", "inputs"}}) {
    const auto r = client_->Post("/api/workspaces/ws1/jobs", b.body, "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << b.body << " " << r->body;
    EXPECT_EQ(Json(r)["field"], b.field) << b.body << " " << r->body;
  }
  EXPECT_EQ(client_->Post("/api/workspaces/nope/jobs", "{}", "application/json")->status, 404);
  EXPECT_EQ(client_->Get("/api/jobs")->body, "[]");
  EXPECT_EQ(client_->Get("/api/jobs/42")->status, 404);
  EXPECT_EQ(client_->Post("/api/jobs/42/stop", "", "application/json")->status, 404);
}

TEST(ApiToken, EveryApiAndFileRequestNeedsTheToken) {
  fmv3d::test::TempDir tmp("api-token");
  MakeWorkspaceRoot(tmp.path());
  ServerOptions o;
  o.ws_root = tmp / "root";
  o.token = "t0k3n-0123456789abcdef";
  RunningServer s(o);
  auto c = s.Client();
  EXPECT_NE(s.server->Url().find("?token=t0k3n-0123456789abcdef"), std::string::npos);
  for (const char* path : {"/api/health", "/api/workspaces", "/api/workspaces/ws1/cameras", "/api/jobs",
                           "/files/ws1/frames/f1.png", "/api/events"}) {
    auto r = c->Get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_EQ(r->status, 401) << path;
    EXPECT_NE(Json(r)["error"].get<std::string>().find("token"), std::string::npos);
    EXPECT_EQ(c->Get(path, {{"Authorization", "Bearer wrong-0123456789abcdef"}})->status, 401) << path;
    EXPECT_EQ(c->Get(path, {{"Authorization", "Bearer t0k3n-0123456789abcde"}})->status, 401) << path;
    EXPECT_EQ(c->Get(std::string(path) + "?token=t0k3n-0123456789abcdeF")->status, 401) << path;
  }
  for (const char* path : {"/api/health", "/api/workspaces", "/files/ws1/frames/f1.png"}) {
    EXPECT_EQ(c->Get(path, {{"Authorization", "Bearer t0k3n-0123456789abcdef"}})->status, 200) << path;
    EXPECT_EQ(c->Get(std::string(path) + "?token=t0k3n-0123456789abcdef")->status, 200) << path;
  }
  EXPECT_EQ(c->Post("/api/workspaces", R"({"name": "x"})", "application/json")->status, 401);
  EXPECT_FALSE(fs::exists(tmp / "root" / "x"));
  // The page itself needs no token (it has none until it reads it from its own URL).
  EXPECT_NE(c->Get("/")->status, 401);
}

TEST(ApiToken, NonLoopbackHostsRequireAToken) {
  fmv3d::test::TempDir tmp("api-host");
  ServerOptions o;
  o.ws_root = tmp.path();
  o.host = "0.0.0.0";
  EXPECT_THROW(o.Check(), Error);
  o.token = RandomToken();
  EXPECT_EQ(o.token.size(), 64u);
  EXPECT_NE(o.token, RandomToken());
  EXPECT_NO_THROW(o.Check());
  o.host = "127.0.0.1";
  o.token.clear();
  EXPECT_NO_THROW(o.Check());
  std::ofstream(tmp / "short") << "abc\n";
  EXPECT_THROW(ReadTokenFile(tmp / "short"), Error);
  std::ofstream(tmp / "good") << "  0123456789abcdefXYZ  \nsecond line\n";
  EXPECT_EQ(ReadTokenFile(tmp / "good"), "0123456789abcdefXYZ");
  EXPECT_THROW(ReadTokenFile(tmp / "absent"), Error);
}

}  // namespace
}  // namespace fmv3d::server::test
