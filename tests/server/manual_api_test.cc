// The hand tools' endpoints (docs/console-api.md, "Hand tools") against a server in-process: frames with their
// state, keypoints, a pair's matches and its fundamental matrix, tie points and GCPs (valid, then every kind of
// bad input: a clear 400 naming the item and nothing written), gcp_list.txt export, and the calibration runs.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include "fmv3d/core/files.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/io/colmap_model.h"
#include "server_fixture.h"

namespace fmv3d::server::test {
namespace {

namespace fs = std::filesystem;

std::string ReadText(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class ManualApi : public ::testing::Test {
 protected:
  void SetUp() override {
    MakeWorkspaceRoot(tmp_.path());
    ws_ = tmp_ / "root" / "ws1";
    // Features for both frames: the projections of a few ground points (so that the pair's inliers are real
    // correspondences) plus random extra keypoints; matches.bin with the ground points as the pair's inliers.
    const core::Reconstruction rec = io::ReadColmapText(ws_ / "sparse");
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(5, 170);
    features::FeatureSet fs_[2];
    for (int k = 0; k < 2; ++k) {
      const core::Image& im = rec.images.at(k + 1);
      fs_[k].image_name = im.name;
      fs_[k].width = 320, fs_[k].height = 180;
      for (int p = 0; p < 8; ++p) {
        const Eigen::Vector3d X(1.0 + 0.5 * p, -1.0 + 0.3 * p, 0.2 * (p % 3));
        const Eigen::Vector2d x = rec.cameras.at(1).Project(im.pose.R() * X + im.pose.t);
        fs_[k].keypoints.push_back({float(x.x()), float(x.y()), 2.0f, 0.5f});
        truth_[k].push_back(x);
      }
      for (int p = 0; p < 20; ++p) fs_[k].keypoints.push_back({u(rng), u(rng), 1.5f, 0.f});
      fs_[k].descriptors = features::Descriptors::Zero(static_cast<int>(fs_[k].keypoints.size()), 128);
      for (int r = 0; r < fs_[k].descriptors.rows(); ++r)
        for (int c = 0; c < 128; ++c) fs_[k].descriptors(r, c) = static_cast<uint8_t>(rng() % 64);
      fs_[k].colors.assign(fs_[k].keypoints.size(), Eigen::Matrix<uint8_t, 3, 1>(1, 2, 3));
      core::EnsureDirectory(ws_ / "features");
      features::WriteFeatures(fs_[k], features::FeaturePath(ws_ / "features", im.name));
    }
    features::VerifiedPair pair;
    pair.image_id1 = 1, pair.image_id2 = 2;
    for (uint32_t p = 0; p < 8; ++p) pair.inliers.push_back({p, p});
    core::EnsureDirectory(ws_ / "matches");
    features::WriteMatches({pair}, features::MatchesPath(ws_ / "matches"));
    core::WriteJson(ws_ / "report" / "sparse.json", {{"left_out", nlohmann::json::array()}});

    ServerOptions o;
    o.ws_root = tmp_ / "root";
    o.asset_dir = tmp_ / "assets";
    o.executable = FMV3D_CLI;
    server_ = std::make_unique<RunningServer>(o);
    client_ = server_->Client();
  }
  httplib::Result Put(const std::string& path, const std::string& body, const char* type = "application/json") {
    return client_->Put(path, body, type);
  }
  fmv3d::test::TempDir tmp_{"manual-api"};
  fs::path ws_;
  std::vector<Eigen::Vector2d> truth_[2];
  std::unique_ptr<RunningServer> server_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(ManualApi, FramesKeypointsAndPair) {
  auto r = client_->Get("/api/workspaces/ws1/frames");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const auto frames = Json(r)["frames"];
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0]["name"], "f1.png");
  EXPECT_EQ(frames[0]["width"], 320);
  EXPECT_TRUE(frames[0]["registered"].get<bool>());
  EXPECT_TRUE(frames[0]["left_out"].is_null());

  r = client_->Get("/api/workspaces/ws1/frames/f1.png/keypoints");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(Json(r)["count"], 28);
  EXPECT_EQ(Json(r)["keypoints"].size(), 28u * 4);
  EXPECT_NEAR(Json(r)["keypoints"][0].get<double>(), truth_[0][0].x(), 1e-3);
  r = client_->Get("/api/workspaces/ws1/frames/nope.png/keypoints");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 404);
  EXPECT_NE(Json(r)["error"].get<std::string>().find("nope.png"), std::string::npos);

  r = client_->Get("/api/workspaces/ws1/pair?a=f2.png&b=f1.png");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const auto pair = Json(r);
  ASSERT_EQ(pair["inliers"].size(), 8u);
  EXPECT_EQ(pair["F_source"], "poses");
  // Order follows the request (a = f2): each inlier's a-position is f2's keypoint.
  const auto& m0 = pair["inliers"][0];
  EXPECT_NEAR(m0[2].get<double>(), truth_[1][0].x(), 1e-3);
  EXPECT_NEAR(m0[4].get<double>(), truth_[0][0].x(), 1e-3);
  // x_bᵀ F x_a = 0 for every true correspondence (distance to the epipolar line well below a pixel).
  Eigen::Matrix3d F;
  for (int i = 0; i < 9; ++i) F(i / 3, i % 3) = pair["F"][i].get<double>();
  for (int p = 0; p < 8; ++p) {
    const Eigen::Vector3d xa(truth_[1][p].x(), truth_[1][p].y(), 1), xb(truth_[0][p].x(), truth_[0][p].y(), 1);
    const Eigen::Vector3d l = F * xa;
    EXPECT_LT(std::abs(xb.dot(l)) / l.head<2>().norm(), 1e-3) << "point " << p;
  }
  r = client_->Get("/api/workspaces/ws1/pair?a=f1.png&b=f1.png");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  r = client_->Get("/api/workspaces/ws1/pair?a=f1.png");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  EXPECT_EQ(Json(r)["field"], "b");
}

TEST_F(ManualApi, TiePointsSavedWholeOrNotAtAll) {
  auto r = client_->Get("/api/workspaces/ws1/tiepoints");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  EXPECT_TRUE(Json(r)["tie_points"].empty());

  const std::string good = R"({"format": "fmv3d-tiepoints", "version": 1,
    "tie_points": [{"id": "t1", "observations": [{"frame": "f1.png", "x": 10.5, "y": 20}, {"frame": "f2.png", "x": 30, "y": 40}]}],
    "keypoints": [{"id": "k1", "frame": "f1.png", "x": 100, "y": 50}],
    "deleted_matches": [{"frame1": "f1.png", "frame2": "f2.png", "feature1": 3, "feature2": 3}]})";
  r = Put("/api/workspaces/ws1/tiepoints", good);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const fs::path file = ws_ / "manual" / "tiepoints.json";
  ASSERT_TRUE(fs::exists(file));
  const std::string saved = ReadText(file);
  r = client_->Get("/api/workspaces/ws1/tiepoints");
  ASSERT_TRUE(r);
  EXPECT_EQ(Json(r)["tie_points"][0]["observations"][1]["x"], 30.0);
  EXPECT_EQ(Json(r)["deleted_matches"].size(), 1u);

  struct Bad {
    std::string body, expect;
  };
  const std::vector<Bad> bad = {
      {R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t1", "observations": [{"frame": "f1.png", "x": 1, "y": 2}, {"frame": "f9.png", "x": 3, "y": 4}]}]})",
       "f9.png"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t1", "observations": [{"frame": "f1.png", "x": 1, "y": 2}, {"frame": "f2.png", "x": 400, "y": 4}]}]})",
       "outside"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t2", "observations": [{"frame": "f1.png", "x": 1, "y": 2}]}]})",
       "t2"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "deleted_matches": [{"frame1": "f1.png", "frame2": "f2.png", "feature1": 999, "feature2": 0}]})",
       "999"},
      {"not json", "JSON"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t3", "observations": [{"frame": "f1.png", "x": 1, "y": 2}, {"frame": "f1.png", "x": 3, "y": 4}]}]})",
       "one per frame"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "tie_points": [{"id": "t4", "observations": [{"frame": "f1.png", "x": -1, "y": 2}, {"frame": "f2.png", "x": 3, "y": 4}]}]})",
       "outside"},
      {R"({"format": "fmv3d-tiepoints", "version": 1, "keypoints": [{"id": "k9", "frame": "f9.png", "x": 1, "y": 2}]})",
       "k9"},
  };
  for (const auto& b : bad) {
    r = Put("/api/workspaces/ws1/tiepoints", b.body);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << b.body;
    EXPECT_NE(Json(r)["error"].get<std::string>().find(b.expect), std::string::npos) << Json(r)["error"];
    EXPECT_EQ(ReadText(file), saved) << "written half-way by " << b.body;
  }
}

TEST_F(ManualApi, GcpsJsonImportExportAndBadInput) {
  const std::string good = R"({"crs": "EPSG:32632", "points": [
    {"name": "g1", "x": 500010, "y": 5200020, "z": 410.5, "check": false,
     "observations": [{"frame": "f1.png", "x": 10, "y": 20}, {"frame": "f2.png", "x": 30, "y": 40}]},
    {"name": "c1", "x": 500030, "y": 5200040, "z": 411, "check": true,
     "observations": [{"frame": "f1.png", "x": 50, "y": 60}, {"frame": "f2.png", "x": 70, "y": 80}]}]})";
  auto r = Put("/api/workspaces/ws1/gcps", good);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const fs::path file = ws_ / "manual" / "gcp_list.txt";
  const std::string saved = ReadText(file);
  EXPECT_EQ(saved.substr(0, 11), "EPSG:32632\n");
  EXPECT_NE(saved.find("f2.png c1 check"), std::string::npos) << saved;
  r = client_->Get("/api/workspaces/ws1/gcps");
  ASSERT_TRUE(r);
  const auto g = Json(r);
  ASSERT_EQ(g["points"].size(), 2u);
  EXPECT_TRUE(g["points"][1]["check"].get<bool>());
  EXPECT_EQ(g["points"][0]["observations"].size(), 2u);
  // Export is the file itself; importing it again gives the same file.
  r = client_->Get("/api/workspaces/ws1/gcp_list.txt");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  EXPECT_EQ(r->body, saved);
  r = Put("/api/workspaces/ws1/gcps", saved, "text/plain");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  EXPECT_EQ(ReadText(file), saved);

  struct Bad {
    std::string body, type, expect;
  };
  const std::vector<Bad> bad = {
      {"EPSG:32632\n500000 5200000 400 10 10 f1.png a\n500000 5200000 oops 10 10 f2.png a\n", "text/plain", ":3:"},
      {"EPSG:999999\n500000 5200000 400 10 10 f1.png a\n500000 5200000 400 10 10 f2.png a\n", "text/plain", "999999"},
      {"EPSG:32632\n500000 5200000 400 10 10 f1.png a\n500000 5200000 400 10 10 f7.png a\n", "text/plain", "f7.png"},
      {"EPSG:32632\n500000 5200000 400 10 10 f1.png a\n500000 5200000 400 10 999 f2.png a\n", "text/plain", "outside"},
      {"EPSG:32632\n500000 5200000 400 10 10 f1.png lonely\n", "text/plain", "lonely"},
      {R"({"crs": "EPSG:4326", "points": [{"name": "g1", "x": 8, "y": 47, "z": 500, "observations": [{"frame": "f1.png", "x": 1, "y": 1}]}]})",
       "application/json", "at least 2"},
      {R"({"crs": "EPSG:0", "points": []})", "application/json", "EPSG:0"},
      {"EPSG:4326\n200 47 400 10 10 f1.png a\n200 47 400 10 10 f2.png a\n", "text/plain", "is not a place"},
      {"EPSG:32632\n500000 5200000 400 10 10 f1.png a\n500000 5200000 400 12 10 f1.png a\n", "text/plain",
       "clicked a second time in frame \"f1.png\""},
      {"", "text/plain", "empty file"},
      {"500000 5200000 400 10 10 f1.png a\n", "text/plain", ":1: CRS"},
  };
  for (const auto& b : bad) {
    r = Put("/api/workspaces/ws1/gcps", b.body, b.type.c_str());
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << b.body;
    EXPECT_NE(Json(r)["error"].get<std::string>().find(b.expect), std::string::npos) << Json(r)["error"];
    EXPECT_EQ(ReadText(file), saved) << "written half-way by " << b.body;
  }
}

TEST_F(ManualApi, CalibrationRequestsAndFailure) {
  auto r = client_->Get("/api/workspaces/ws1/calibration");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  EXPECT_EQ(Json(r)["state"], "none");
  struct Bad {
    std::string body, field;
  };
  const std::vector<Bad> bad = {
      {R"({"images": ["frames/f1.png", "frames/f2.png"]})", "images"},
      {R"({"images": ["frames/f1.png", "frames/f2.png", "frames/f1.png"], "board": "9by6"})", "board"},
      {R"({"images": ["frames/f1.png", "frames/f2.png", "frames/f1.png"], "square": -1})", "square"},
      {R"({"images": ["frames/f1.png", "frames/f2.png", "../outside/x.png"]})", "images"},
      {R"({"images": ["frames/f1.png", "frames/f2.png", "frames/none.png"]})", "images"},
      {R"({"images": [], "colour": 1})", "colour"},
  };
  for (const auto& b : bad) {
    r = client_->Post("/api/workspaces/ws1/calibration", b.body, "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << b.body;
    EXPECT_EQ(Json(r)["field"], b.field) << r->body;
  }
  r = client_->Post("/api/workspaces/ws1/calibration/save", R"({"name": "cam"})", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 409);
  // Three files that are not images: the run starts, then fails with calibrate's message in the log.
  r = client_->Post("/api/workspaces/ws1/calibration",
                    R"({"images": ["frames/f1.png", "frames/f2.png", "frames/f1.png"], "board": "9x6", "square": 0.1})",
                    "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 202) << r->body;
  nlohmann::json c;
  for (int i = 0; i < 300; ++i) {
    c = Json(client_->Get("/api/workspaces/ws1/calibration"));
    if (c["state"] != "running") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_EQ(c["state"], "failed") << c.dump();
  EXPECT_FALSE(c["log"].empty());
  EXPECT_EQ(c["request"]["images"].size(), 3u);
}

}  // namespace
}  // namespace fmv3d::server::test
