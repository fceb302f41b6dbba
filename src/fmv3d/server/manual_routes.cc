// The console's hand tools (docs/console-api.md, "Hand tools"): frames with their state, a frame's keypoints,
// the matches of a pair, tie points and GCPs entered by the operator, and the chessboard calibration window.
#include <algorithm>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "fmv3d/calib/camera_file.h"
#include "fmv3d/calib/sensor_db.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/features/feature_io.h"
#include "fmv3d/features/matcher.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/io/tiepoints.h"
#include "fmv3d/server/manual_inputs.h"
#include "fmv3d/server/process.h"
#include "fmv3d/server/routes.h"
#include "fmv3d/server/validation.h"

namespace fmv3d::server {

namespace fs = std::filesystem;

namespace {

io::FramesIndex RequireFrames(const fs::path& dir) {
  const fs::path p = core::Workspace(dir).frames_json();
  if (!fs::exists(p)) throw RequestError(404, "no frames yet (run the frames stage first)");
  return io::ReadFramesIndex(p);
}

const io::FrameRecord& FindFrame(const io::FramesIndex& index, const std::string& name, const std::string& field) {
  for (const auto& f : index.frames)
    if (f.name == name) return f;
  throw RequestError(404, "'" + field + "': no frame '" + name + "' in frames/frames.json", field);
}

// Registered frames by name (empty when there is no sparse model).
std::map<std::string, const core::Image*> RegisteredByName(const core::Reconstruction& rec) {
  std::map<std::string, const core::Image*> out;
  for (const auto& [id, im] : rec.images) out[im.name] = &im;
  return out;
}

std::optional<core::Reconstruction> ReadModel(const fs::path& dir) {
  const core::Workspace ws(dir);
  if (!fs::exists(ws.sparse_dir() / "images.txt")) return std::nullopt;
  return io::ReadColmapText(ws.sparse_dir());
}

nlohmann::json FramesJson(const fs::path& dir) {
  const io::FramesIndex index = RequireFrames(dir);
  const auto model = ReadModel(dir);
  std::map<std::string, const core::Image*> registered;
  if (model) registered = RegisteredByName(*model);
  std::map<std::string, std::string> left_out;
  const fs::path sparse_report = core::Workspace(dir).report_dir() / "sparse.json";
  if (fs::exists(sparse_report)) {
    const nlohmann::json r = core::ReadJson(sparse_report);
    if (r.contains("left_out") && r["left_out"].is_array())
      for (const auto& l : r["left_out"]) left_out[l.value("image", "")] = l.value("reason", "");
  }
  nlohmann::json frames = nlohmann::json::array();
  for (size_t i = 0; i < index.frames.size(); ++i) {
    const auto& f = index.frames[i];
    const auto* cam = index.FindCamera(f.camera_id);
    nlohmann::json j = {{"id", i + 1},
                        {"name", f.name},
                        {"width", cam ? cam->camera.width : 0},
                        {"height", cam ? cam->camera.height : 0},
                        {"registered", registered.count(f.name) > 0},
                        {"features", fs::exists(features::FeaturePath(core::Workspace(dir).features_dir(), f.name))}};
    if (model && !registered.count(f.name))
      j["left_out"] = left_out.count(f.name) ? left_out[f.name] : "not in the largest model";
    else
      j["left_out"] = nullptr;
    frames.push_back(j);
  }
  return {{"frames", frames}, {"has_model", model.has_value()}};
}

nlohmann::json KeypointsJson(const fs::path& dir, const std::string& name) {
  const io::FramesIndex index = RequireFrames(dir);
  FindFrame(index, name, "frame");
  const fs::path p = features::FeaturePath(core::Workspace(dir).features_dir(), name);
  if (!fs::exists(p)) throw RequestError(404, "no features for '" + name + "' yet (run the features stage)");
  const features::FeatureSet fs = features::ReadFeatures(p);
  std::vector<float> flat;
  flat.reserve(fs.keypoints.size() * 4);
  for (const auto& k : fs.keypoints) flat.insert(flat.end(), {k.x, k.y, k.scale, k.orientation});
  return {
      {"frame", name}, {"width", fs.width}, {"height", fs.height}, {"count", fs.keypoints.size()}, {"keypoints", flat}};
}

// F with x2ᵀ F x1 = 0 for pixel coordinates of two posed images (distortion ignored: for drawing lines).
Eigen::Matrix3d FundamentalFromPoses(const core::Reconstruction& rec, const core::Image& a, const core::Image& b) {
  const Eigen::Matrix3d R1 = a.pose.R(), R2 = b.pose.R();
  const Eigen::Matrix3d R = R2 * R1.transpose();
  const Eigen::Vector3d t = b.pose.t - R * a.pose.t;
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  const Eigen::Matrix3d K1 = rec.cameras.at(a.camera_id).K(), K2 = rec.cameras.at(b.camera_id).K();
  return K2.inverse().transpose() * tx * R * K1.inverse();
}

nlohmann::json Mat9(const Eigen::Matrix3d& m) {
  nlohmann::json out = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.push_back(m(r, c));
  return out;
}

// The pair (a, b): verified inliers from matches/matches.bin, the descriptor matches geometric verification
// rejected (matched again here with the match stage's default ratio and mutual check), and F from the poses
// when both frames are registered, else from the verified pair.
nlohmann::json PairJson(const fs::path& dir, const std::string& a, const std::string& b) {
  const io::FramesIndex index = RequireFrames(dir);
  FindFrame(index, a, "a");
  FindFrame(index, b, "b");
  if (a == b) throw RequestError(400, "'b': choose a second frame different from the first", "b");
  uint32_t ida = 0, idb = 0;
  for (size_t i = 0; i < index.frames.size(); ++i) {
    if (index.frames[i].name == a) ida = uint32_t(i + 1);
    if (index.frames[i].name == b) idb = uint32_t(i + 1);
  }
  const fs::path pa = features::FeaturePath(core::Workspace(dir).features_dir(), a),
                 pb = features::FeaturePath(core::Workspace(dir).features_dir(), b);
  if (!fs::exists(pa) || !fs::exists(pb)) throw RequestError(404, "no features for this pair yet");
  const features::FeatureSet fa = features::ReadFeatures(pa), fb = features::ReadFeatures(pb);
  const bool swap = ida > idb;  // matches.bin stores image_id1 < image_id2
  std::set<std::pair<uint32_t, uint32_t>> inlier_set;
  nlohmann::json F = nullptr;
  std::string f_source;
  const fs::path mp = features::MatchesPath(core::Workspace(dir).matches_dir());
  if (fs::exists(mp)) {
    for (const auto& p : features::ReadMatches(mp)) {
      if (p.image_id1 != std::min(ida, idb) || p.image_id2 != std::max(ida, idb)) continue;
      for (const auto& m : p.inliers)
        inlier_set.insert(swap ? std::make_pair(m.idx2, m.idx1) : std::make_pair(m.idx1, m.idx2));
      if (!p.F.isZero()) {
        F = Mat9(swap ? Eigen::Matrix3d(p.F.transpose()) : p.F);
        f_source = "matches";
      }
    }
  }
  if (const auto model = ReadModel(dir)) {
    const auto reg = RegisteredByName(*model);
    if (reg.count(a) && reg.count(b)) {
      F = Mat9(FundamentalFromPoses(*model, *reg.at(a), *reg.at(b)));
      f_source = "poses";
    }
  }
  nlohmann::json inliers = nlohmann::json::array(), rejected = nlohmann::json::array();
  auto add = [&](nlohmann::json& to, uint32_t i, uint32_t j) {
    if (i >= fa.keypoints.size() || j >= fb.keypoints.size()) return;
    to.push_back({i, j, fa.keypoints[i].x, fa.keypoints[i].y, fb.keypoints[j].x, fb.keypoints[j].y});
  };
  for (const auto& [i, j] : inlier_set) add(inliers, i, j);
  if (fa.keypoints.size() > 0 && fb.keypoints.size() > 0) {
    features::ImageDescriptors da(fa.descriptors, ida), db(fb.descriptors, idb);
    for (const auto& m : features::MatchDescriptors(da, db, features::MatchOptions{}))
      if (!inlier_set.count({m.idx1, m.idx2})) add(rejected, m.idx1, m.idx2);
  }
  return {{"a", a},
          {"b", b},
          {"inliers", inliers},
          {"rejected", rejected},
          {"F", F},
          {"F_source", f_source.empty() ? nlohmann::json() : nlohmann::json(f_source)}};
}

enum class CalibrationState { kNone, kRunning, kDone, kFailed };
const char* CalibrationStateName(CalibrationState s) {
  switch (s) {
    case CalibrationState::kNone:
      return "none";
    case CalibrationState::kRunning:
      return "running";
    case CalibrationState::kDone:
      return "done";
    case CalibrationState::kFailed:
      return "failed";
  }
  return "none";
}

// Chessboard calibration runs (`fmv3d calibrate`), at most one per workspace, tracked by pid.
class CalibrationRuns {
 public:
  void Start(const fs::path& exe, const fs::path& ws_dir, const CalibrationRequest& r,
             const std::vector<fs::path>& images) {
    std::lock_guard<std::mutex> lock(mutex_);
    Poll(ws_dir);
    if (running_.count(ws_dir)) throw RequestError(409, "a calibration is already running in this workspace");
    const fs::path out = ws_dir / "calib";
    core::EnsureDirectory(out);
    std::error_code ec;
    fs::remove_all(out / "camera-corners", ec);
    fs::remove_all(out / "camera-frames", ec);
    for (const char* f : {"camera.json", "camera.yaml", "camera-distortion.png", "calibrate.log"})
      fs::remove(out / f, ec);
    std::vector<std::string> argv = {exe.string(), "calibrate",
                                     "--board",    std::to_string(r.cols) + "x" + std::to_string(r.rows),
                                     "--square",   std::to_string(r.square)};
    nlohmann::json names = nlohmann::json::array();
    for (const auto& i : images) argv.push_back(i.string()), names.push_back(fs::relative(i, ws_dir).string());
    for (const auto& d : r.drop) argv.insert(argv.end(), {"--drop", d});
    argv.insert(argv.end(), {"-o", (out / "camera.json").string()});
    core::WriteJson(
        out / "request.json",
        {{"board", {{"cols", r.cols}, {"rows", r.rows}}}, {"square", r.square}, {"images", names}, {"drop", r.drop}});
    running_[ws_dir] = SpawnProcess(argv, out / "calibrate.log");
  }
  CalibrationState State(const fs::path& ws_dir) {
    std::lock_guard<std::mutex> lock(mutex_);
    Poll(ws_dir);
    if (running_.count(ws_dir)) return CalibrationState::kRunning;
    const fs::path out = ws_dir / "calib";
    if (fs::exists(out / "camera.json")) return CalibrationState::kDone;
    if (fs::exists(out / "calibrate.log")) return CalibrationState::kFailed;
    return CalibrationState::kNone;
  }

 private:
  void Poll(const fs::path& ws_dir) {
    const auto it = running_.find(ws_dir);
    if (it != running_.end() && PollExit(it->second)) running_.erase(it);
  }
  std::mutex mutex_;
  std::map<fs::path, pid_t> running_;
};

std::vector<std::string> LastLines(const fs::path& path, size_t n) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  if (lines.size() > n) lines.erase(lines.begin(), lines.end() - static_cast<std::ptrdiff_t>(n));
  return lines;
}

nlohmann::json CalibrationJson(CalibrationRuns& runs, const fs::path& dir) {
  const fs::path out = dir / "calib";
  const CalibrationState state = runs.State(dir);
  nlohmann::json j = {{"state", CalibrationStateName(state)}, {"log", LastLines(out / "calibrate.log", 200)}};
  j["request"] = fs::exists(out / "request.json") ? core::ReadJson(out / "request.json") : nlohmann::json();
  j["result"] = state == CalibrationState::kDone ? core::ReadJson(out / "camera.json") : nlohmann::json();
  // Images uploaded to the workspace, candidates for the board images.
  std::vector<std::string> uploads;
  std::error_code ec;
  if (fs::is_directory(dir / "uploads", ec))
    for (const auto& e : fs::directory_iterator(dir / "uploads", ec)) {
      if (e.is_regular_file(ec) && (io::HasImageExtension(e.path()) || io::HasVideoExtension(e.path())))
        uploads.push_back("uploads/" + e.path().filename().string());
    }
  std::sort(uploads.begin(), uploads.end());
  j["uploads"] = uploads;
  if (state == CalibrationState::kDone) {
    j["distortion_png"] = "calib/camera-distortion.png";
    j["corners_dir"] = "calib/camera-corners";
    if (j["result"].contains("frames_dir")) j["frames_dir"] = "calib/camera-frames";  // frames of videos
  }
  return j;
}

fs::path WorkspaceFile(const fs::path& dir, const std::string& rel, const std::string& field) {
  const auto p = ResolveInside(dir, rel);
  if (!p) throw RequestError(400, "'" + field + "': " + rel + ": " + p.why(), field);
  std::error_code ec;
  if (!fs::is_regular_file(*p, ec)) throw RequestError(400, "'" + field + "': " + rel + " is not a file", field);
  return *p;
}

io::FrameTable FrameTable(const fs::path& dir) {
  io::FrameTable table = io::FrameTableOf(RequireFrames(dir));
  // Deleted matches index the automatic keypoints: their counts when the features are there.
  for (auto& [name, limits] : table) {
    const fs::path p = features::FeaturePath(core::Workspace(dir).features_dir(), name);
    if (fs::exists(p)) limits.num_keypoints = features::ReadFeatures(p).keypoints.size();
  }
  return table;
}

}  // namespace

void RegisterManualRoutes(httplib::Server& http, Context& ctx) {
  const std::string ws = R"(/api/workspaces/([^/]+))";
  http.Get(ws + "/frames", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] { SendJson(res, 200, FramesJson(WorkspaceDir(ctx, req.matches[1]))); });
  });
  http.Get(ws + "/frames/([^/]+)/keypoints", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] { SendJson(res, 200, KeypointsJson(WorkspaceDir(ctx, req.matches[1]), req.matches[2])); });
  });
  http.Get(ws + "/pair", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (!req.has_param("a")) throw RequestError(400, "'a' is required (a frame name)", "a");
      if (!req.has_param("b")) throw RequestError(400, "'b' is required (a frame name)", "b");
      SendJson(res, 200, PairJson(dir, req.get_param_value("a"), req.get_param_value("b")));
    });
  });
  http.Get(ws + "/tiepoints", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res,
          [&] { SendJson(res, 200, LoadTiePoints(WorkspaceDir(ctx, req.matches[1]) / "manual" / "tiepoints.json")); });
  });
  http.Put(ws + "/tiepoints", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (req.body.size() > kMaxJsonBody) throw RequestError(413, "the JSON body is larger than 1 MB", "body");
      const io::FrameTable frames = FrameTable(dir);
      core::EnsureDirectory(dir / "manual");
      SendJson(res, 200, SaveTiePoints(req.body, frames, dir / "manual" / "tiepoints.json"));
    });
  });
  http.Get(ws + "/gcps", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] { SendJson(res, 200, LoadGcps(WorkspaceDir(ctx, req.matches[1]) / "manual" / "gcp_list.txt")); });
  });
  // PUT JSON ({"crs", "points"}) or the text of a gcp_list.txt (import); both are checked whole first.
  http.Put(ws + "/gcps", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (req.body.size() > kMaxJsonBody) throw RequestError(413, "the body is larger than 1 MB", "body");
      const io::FrameTable frames = io::FrameTableOf(RequireFrames(dir));
      const bool is_json = req.get_header_value("Content-Type").rfind("application/json", 0) == 0;
      core::EnsureDirectory(dir / "manual");
      const fs::path path = dir / "manual" / "gcp_list.txt";
      SendJson(res, 200, is_json ? SaveGcpJson(req.body, frames, path) : SaveGcpText(req.body, frames, path));
    });
  });
  http.Get(ws + "/gcp_list.txt", [&ctx](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path p = WorkspaceDir(ctx, req.matches[1]) / "manual" / "gcp_list.txt";
      if (!fs::exists(p)) throw RequestError(404, "no manual/gcp_list.txt in this workspace");
      res.set_header("Content-Disposition", "attachment; filename=\"gcp_list.txt\"");
      SendFile(res, p);
    });
  });

  auto runs = std::make_shared<CalibrationRuns>();
  http.Get(ws + "/calibration", [&ctx, runs](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] { SendJson(res, 200, CalibrationJson(*runs, WorkspaceDir(ctx, req.matches[1]))); });
  });
  http.Post(ws + "/calibration", [&ctx, runs](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (req.body.size() > kMaxJsonBody) throw RequestError(413, "the JSON body is larger than 1 MB", "body");
      const CalibrationRequest r = ParseCalibrationRequest(req.body);
      std::vector<fs::path> images;
      for (const auto& i : r.images) images.push_back(WorkspaceFile(dir, i, "images"));
      runs->Start(ctx.options.executable, dir, r, images);
      SendJson(res, 202, CalibrationJson(*runs, dir));
    });
  });
  http.Post(ws + "/calibration/save", [&ctx, runs](const httplib::Request& req, httplib::Response& res) {
    Guard(res, [&] {
      const fs::path dir = WorkspaceDir(ctx, req.matches[1]);
      if (req.body.size() > kMaxJsonBody) throw RequestError(413, "the JSON body is larger than 1 MB", "body");
      const std::string name = ParseSensorName(req.body);
      if (runs->State(dir) != CalibrationState::kDone)
        throw RequestError(409, "no finished calibration to save (run it first)");
      const nlohmann::json result = core::ReadJson(dir / "calib" / "camera.json");
      const core::Camera camera = calib::ReadCameraFile(dir / "calib" / "camera.json");
      const fs::path db = calib::UserDatabasePath();
      char note[160];
      std::snprintf(note, sizeof(note), "chessboard calibration in the console, %zu images, RMS %.3f px",
                    result.value("images", nlohmann::json::array()).size(), result.value("rms", 0.0));
      calib::SaveUserSensor(db, name, camera, note);
      SendJson(res, 200, {{"name", name}, {"database", db.string()}});
    });
  });
}

}  // namespace fmv3d::server
