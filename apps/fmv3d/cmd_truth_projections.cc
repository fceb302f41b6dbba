// `fmv3d truth-projections SYNTH [--points N] [--in FRAMES] [--ws WS] [--noise PX] [--format json|tiepoints|gcp]`:
// scene points of a `fmv3d synth` flight (SYNTH/truth/) with their true pixel positions in every frame that sees
// them — what a test clicks as tie points or GCPs (synth/truth_points.h). json (default): {"points": [{"id",
// "xyz", "observations": [{"frame", "x", "y"}], ("wgs84", "geo", "check")}]}; tiepoints: a manual/tiepoints.json;
// gcp: an OpenDroneMap gcp_list.txt in --crs, the world taken as the ENU frame at --origin (default: the
// flight's geo origin in truth.json).
#include <cstdio>
#include <optional>
#include <sstream>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/workspace.h"
#include "fmv3d/geo/gcp_list.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/frames_index.h"
#include "fmv3d/io/tiepoints.h"
#include "fmv3d/synth/truth_points.h"

namespace fmv3d::app::cmd_truth_projections {
namespace {

std::vector<std::string> SplitList(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

// The synth world's geo origin: --origin when given, else truth.json's (absent for a flight without telemetry).
std::optional<geo::GeoPoint> GeoOrigin(const std::string& option, const std::filesystem::path& synth_dir) {
  if (!option.empty()) {
    geo::GeoPoint g;
    char extra = 0;
    if (std::sscanf(option.c_str(), "%lf,%lf,%lf%c", &g.lat, &g.lon, &g.alt, &extra) != 3)
      throw CLI::ValidationError("--origin", "expected LAT,LON,ALT, e.g. 46.95,7.44,540");
    return g;
  }
  if (!std::filesystem::exists(synth_dir / "truth.json")) return std::nullopt;
  const auto tj = core::ReadJson(synth_dir / "truth.json");
  if (!tj.contains("geo_origin")) return std::nullopt;
  return geo::GeoPoint{tj["geo_origin"].at("lat").get<double>(), tj["geo_origin"].at("lon").get<double>(),
                       tj["geo_origin"].at("alt").get<double>()};
}

nlohmann::json PointsJson(const std::vector<synth::TruthPoint>& points, const std::optional<geo::GeoPoint>& origin,
                          const std::filesystem::path& truth_dir) {
  nlohmann::json arr = nlohmann::json::array();
  std::optional<geo::LocalFrame> frame;
  if (origin) frame.emplace(*origin);
  for (size_t i = 0; i < points.size(); ++i) {
    nlohmann::json obs = nlohmann::json::array();
    for (const auto& o : points[i].observations) obs.push_back({{"frame", o.frame}, {"x", o.x}, {"y", o.y}});
    nlohmann::json p = {{"id", "p" + std::to_string(i + 1)},
                        {"xyz", {points[i].xyz.x(), points[i].xyz.y(), points[i].xyz.z()}},
                        {"observations", obs}};
    if (frame) {
      const geo::GeoPoint g = frame->ToGeodetic(points[i].xyz);
      p["wgs84"] = {{"lat", g.lat}, {"lon", g.lon}, {"alt", g.alt}};
    }
    arr.push_back(p);
  }
  return {{"truth", truth_dir.string()},
          {"pixel_convention", "origin at the top-left corner, pixel centres at +0.5"},
          {"points", arr}};
}

// One line per observation; the last `check` points are marked as check points.
geo::GcpList GcpListOf(const std::vector<synth::TruthPoint>& points, const geo::GeoPoint& origin,
                       const std::string& crs_name, int check_points) {
  const geo::LocalFrame frame(origin);
  const geo::GcpCrs crs(crs_name);
  geo::GcpList list;
  list.crs = crs_name;
  for (size_t i = 0; i < points.size(); ++i) {
    const bool check = static_cast<int>(i) >= static_cast<int>(points.size()) - check_points;
    const Eigen::Vector3d geo = crs.FromWgs84(frame.ToGeodetic(points[i].xyz));
    for (const auto& o : points[i].observations) {
      geo::GcpLine l;
      l.geo = geo;
      l.im_x = o.x;
      l.im_y = o.y;
      l.image = o.frame;
      l.name = (check ? "chk" : "gcp") + std::to_string(i + 1);
      if (check) l.extra = {"check"};
      list.lines.push_back(l);
    }
  }
  return list;
}

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("truth-projections",
                                 "True pixel positions of scene points of a synth flight (for tie-point / GCP tests)");
  struct Args {
    std::string synth, ws, in, frames, format = "json", origin, crs = "EPSG:4326", output;
    int check = 0;
    synth::TruthPointOptions opt;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("SYNTH", a->synth, "Output folder of `fmv3d synth` (with truth/)")->required();
  cmd->add_option("--points", a->opt.points, "Number of scene points (spread over the scene)")->capture_default_str();
  cmd->add_option("--min-frames", a->opt.min_frames, "Frames that must see each point")->capture_default_str();
  cmd->add_option("--in", a->in, "Comma-separated frames every point must be seen in (e.g. a degraded frame)");
  cmd->add_option("--frames", a->frames, "Comma-separated frames whose observations are kept (default: all)");
  cmd->add_option("--ws", a->ws,
                  "Workspace: keep only its frames (frames/frames.json) and check the output against it");
  cmd->add_option("--noise", a->opt.noise_px, "Gaussian noise σ added to each pixel coordinate")->capture_default_str();
  cmd->add_option("--noise-max", a->opt.noise_max_px,
                  "Uniform noise in [-PX, PX] added to each pixel coordinate (a click within ±PX)")
      ->capture_default_str();
  cmd->add_option("--seed", a->opt.seed, "Seed of the noise")->capture_default_str();
  cmd->add_option("--format", a->format, "json | tiepoints | gcp")
      ->check(CLI::IsMember({"json", "tiepoints", "gcp"}))
      ->capture_default_str();
  cmd->add_option("--origin", a->origin, "gcp/json: geo origin LAT,LON,ALT of the synth world (default: truth.json)");
  cmd->add_option("--crs", a->crs, "gcp: CRS of the coordinates (EPSG:<code>, \"WGS84 UTM 32N\", +proj=...)")
      ->capture_default_str();
  cmd->add_option("--check", a->check, "gcp: mark the last N points as check points")->capture_default_str();
  cmd->add_option("-o,--output", a->output, "Write to this file (atomically) instead of stdout");
  cmd->callback([a] {
    namespace fs = std::filesystem;
    const fs::path truth_dir = fs::path(a->synth) / "truth";
    if (!fs::exists(truth_dir / "images.txt"))
      throw Error(a->synth + ": no truth/images.txt (not a `fmv3d synth` output folder)");
    const core::Reconstruction truth = io::ReadColmapText(truth_dir);
    a->opt.required_frames = SplitList(a->in);
    a->opt.allowed_frames = SplitList(a->frames);
    std::optional<io::FrameTable> table;
    if (!a->ws.empty()) {
      const core::Workspace ws(a->ws);
      ws.Require(ws.frames_json(), "frames");
      table = io::FrameTableOf(io::ReadFramesIndex(ws.frames_json()));
      std::vector<std::string> keep;
      for (const auto& [name, limits] : *table)
        if (a->opt.allowed_frames.empty() ||
            std::find(a->opt.allowed_frames.begin(), a->opt.allowed_frames.end(), name) != a->opt.allowed_frames.end())
          keep.push_back(name);
      a->opt.allowed_frames = keep;
    }
    const auto points = synth::SelectTruthPoints(truth, a->opt);
    if (a->check < 0 || a->check >= static_cast<int>(points.size()))
      throw Error("truth-projections: --check must leave at least one control point");
    const std::optional<geo::GeoPoint> origin = GeoOrigin(a->origin, fs::path(a->synth));
    if (a->format == "gcp" && !origin)
      throw Error("truth-projections: --format gcp needs --origin LAT,LON,ALT (the synth world has no geo origin)");
    std::string text;
    if (a->format == "json") {
      text = PointsJson(points, origin, truth_dir).dump(2) + "\n";
    } else if (a->format == "tiepoints") {
      io::TiePoints t;
      for (size_t i = 0; i < points.size(); ++i)
        t.tie_points.push_back({"p" + std::to_string(i + 1), "", points[i].observations});
      if (!a->output.empty()) {
        io::WriteTiePoints(t, a->output, table ? &*table : nullptr);
        return;
      }
      text = io::TiePointsToJson(t).dump(2) + "\n";
    } else {
      const geo::GcpList list = GcpListOf(points, *origin, a->crs, a->check);
      if (!a->output.empty()) {
        geo::WriteGcpList(list, a->output, table ? &*table : nullptr);
        return;
      }
      text = geo::FormatGcpList(list);
    }
    if (a->output.empty()) {
      std::fwrite(text.data(), 1, text.size(), stdout);
    } else {
      core::WriteTextFile(a->output, text);
    }
  });
}

const RegisterCommand reg(1020, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_truth_projections
