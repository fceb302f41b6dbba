#include "server_fixture.h"

#include <fstream>

#include "fmv3d/core/files.h"
#include "fmv3d/core/reconstruction.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/geo/raster.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"

namespace fmv3d::server::test {

namespace fs = std::filesystem;

RunningServer::RunningServer(ServerOptions options) {
  options.port = 0;
  server = std::make_unique<Server>(options);
  port = server->Bind();
  thread = std::thread([this] { server->Run(); });
}

RunningServer::~RunningServer() {
  server->Stop();
  thread.join();
}

std::unique_ptr<httplib::Client> RunningServer::Client() const {
  auto c = std::make_unique<httplib::Client>("127.0.0.1", port);
  c->set_url_encode(false);
  c->set_read_timeout(60, 0);
  return c;
}

void MakeWorkspaceRoot(const fs::path& tmp) {
  const fs::path root = tmp / "root", ws = root / "ws1";
  fs::create_directories(ws / "frames");
  fs::create_directories(ws / "sparse");
  fs::create_directories(ws / "report");
  fs::create_directories(ws / "geo");
  fs::create_directories(tmp / "outside");
  fs::create_directories(root / ".hidden" / "frames");
  core::WriteJson(ws / "project.json", {{"inputs", nlohmann::json::array()}});
  core::WriteJson(root / ".hidden" / "project.json", {{"inputs", nlohmann::json::array()}});
  std::ofstream(tmp / "outside" / "secret.txt") << "secret";
  core::WriteJson(tmp / "outside" / "project.json", {{"inputs", nlohmann::json::array()}});
  fs::create_directory_symlink(tmp / "outside", ws / "escape");
  fs::create_directory_symlink(tmp / "outside", root / "evil");

  // Two cameras 10 m up looking down at points on the ground (model frame = ENU here: similarity identity).
  core::Reconstruction rec;
  rec.cameras[1] = core::Camera::Pinhole(320, 180, 300);
  for (uint32_t id = 1; id <= 2; ++id) {
    core::Image im;
    im.id = id;
    im.camera_id = 1;
    im.name = "f" + std::to_string(id) + ".png";
    Eigen::Matrix3d R;
    R << 1, 0, 0, 0, -1, 0, 0, 0, -1;  // looking down (camera z = −world z)
    im.pose = core::Pose::FromRotationAndCentre(R, Eigen::Vector3d(id * 2.0, 0, 10));
    rec.images[id] = im;
  }
  for (uint64_t p = 1; p <= 5; ++p) {
    core::Point3D pt;
    pt.id = p;
    pt.xyz = {p * 1.0, 0.5 * p, 0};
    pt.rgb << uint8_t(10 * p), 20, 30;
    pt.error = 0.1 * p;
    for (uint32_t id = 1; id <= 2; ++id) {
      auto& im = rec.images[id];
      const Eigen::Vector3d x = im.pose.R() * pt.xyz + im.pose.t;
      im.points2d.push_back(rec.cameras[1].Project(x) + Eigen::Vector2d(0.5, 0));  // 0.5 px off
      im.point3d_ids.push_back(static_cast<int64_t>(p));
      pt.track.push_back({id, static_cast<uint32_t>(im.points2d.size() - 1)});
    }
    rec.points[p] = pt;
  }
  io::WriteColmapText(rec, ws / "sparse");

  io::FramesIndex index;
  io::CameraPrior prior;
  prior.camera = rec.cameras[1];
  prior.prior_source = fmv3d::io::ParsePriorSource("test");
  index.cameras.push_back(prior);
  for (int i = 1; i <= 2; ++i) {
    io::FrameRecord f;
    f.name = "f" + std::to_string(i) + ".png";
    f.telemetry = core::TelemetryFromJson(
        {{"time", i}, {"sensor_latitude", 47.0 + 1e-5 * i}, {"sensor_longitude", 8.0}, {"sensor_altitude_hae", 510.0}});
    index.frames.push_back(f);
    std::ofstream(ws / "frames" / f.name) << "PNG-ish bytes " << i;
  }
  io::WriteFramesIndex(index, ws / "frames" / "frames.json");
  core::WriteJson(ws / "report" / "report.json", {{"cameras", {{"registered", 2}}}, {"test", true}});
  std::ofstream(ws / "report" / "bytes.bin", std::ios::binary) << std::string("0123456789abcdefghij");

  const geo::GeoPoint origin{47.0, 8.0, 500.0};
  const geo::LocalFrame frame(origin);
  nlohmann::json identity = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) identity.push_back({r == 0 ? 1 : 0, r == 1 ? 1 : 0, r == 2 ? 1 : 0, r == 3 ? 1 : 0});
  core::WriteJson(ws / "geo" / "georef.json",
                  {{"origin", {{"lat", origin.lat}, {"lon", origin.lon}, {"alt", origin.alt}}},
                   {"vertical_datum", "WGS84 ellipsoid"},
                   {"utm", {{"zone", frame.utm_zone().zone}, {"north", true}, {"epsg", frame.utm_zone().Epsg()}}},
                   {"similarity", {{"matrix", identity}}}});
  // DSM: 40 x 40 cells of 1 m centred on the origin, height 500 + easting offset / 10 (a known slope).
  const Eigen::Vector3d o = frame.GeodeticToUtm(origin);
  geo::GridSpec g;
  g.min_e = std::floor(o.x()) - 20;
  g.max_n = std::floor(o.y()) + 20;
  g.gsd = 1;
  g.width = g.height = 40;
  g.zone = frame.utm_zone();
  cv::Mat h(40, 40, CV_32F);
  for (int r = 0; r < 40; ++r)
    for (int c = 0; c < 40; ++c) h.at<float>(r, c) = static_cast<float>(500 + (g.CellCentre(r, c).x() - o.x()) / 10);
  h.at<float>(0, 0) = geo::kNoData;
  geo::WriteHeightGeoTiff(ws / "geo" / "dsm.tif", g, h);
}

}  // namespace fmv3d::server::test
