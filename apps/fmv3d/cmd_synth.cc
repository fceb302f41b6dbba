// `fmv3d synth`: render a synthetic flight over a fixed scene and write frames or a video plus exact
// ground truth. Output layout (see synth/synth.h):
//   DIR/frames/flight-000000.png ...  (png/jpg)   or   DIR/flight.mp4 | DIR/flight.ts  (video)
//   DIR/truth/{cameras,images,points3D}.txt        COLMAP text model; images named flight-NNNNNN.png
//   DIR/scene.obj (+ .mtl, textures)               scene mesh in world metres, z up
//   DIR/truth.json                                 characteristic_length, bounds, seed, fps, all options
//   DIR/depth/flight-NNNNNN.tiff                   (--depth) float depth maps, camera z in metres
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "command.h"
#include "fmv3d/core/error.h"
#include "fmv3d/geo/geodesy.h"
#include "fmv3d/synth/synth.h"

namespace fmv3d::app::cmd_synth {
namespace {

std::vector<double> ParseList(const std::string& s) {
  std::vector<double> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    size_t used = 0;
    double v = 0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      throw Error("'" + s + "' is not a comma-separated list of numbers");
    }
    if (used != item.size() || !std::isfinite(v)) throw Error("'" + s + "' is not a comma-separated list of numbers");
    out.push_back(v);
  }
  return out;
}

const CLI::Validator kSize(
    [](std::string& s) -> std::string {
      int w = 0, h = 0;
      char x = 0, extra = 0;
      if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
        return "size must be WIDTHxHEIGHT, e.g. 1280x720";
      if (w <= 0 || h <= 0 || w > 16384 || h > 16384) return "size must be between 1x1 and 16384x16384";
      return "";
    },
    "WxH");

const CLI::Validator kList4(
    [](std::string& s) -> std::string {
      try {
        if (ParseList(s).size() != 4) return "expected 4 comma-separated numbers k1,k2,p1,p2";
      } catch (const Error& e) {
        return e.what();
      }
      return "";
    },
    "k1,k2,p1,p2");

const CLI::Validator kList3(
    [](std::string& s) -> std::string {
      try {
        if (ParseList(s).size() != 3) return "expected 3 comma-separated numbers X,Y,Z";
      } catch (const Error& e) {
        return e.what();
      }
      return "";
    },
    "X,Y,Z");

// What the command line binds: SynthOptions' own fields directly, the rest as given (parsed by ToSynthOptions),
// and the options whose presence matters.
struct SynthFlags {
  synth::SynthOptions o;
  std::string scene = "building", path = "orbit", format = "png";  // spellings, parsed by ToSynthOptions
  std::string size = "1280x720", distortion, look_at, grid_overlap, geo_origin = "38.16,-77.35,60", output;
  double focal = 0, altitude = 0, radius = 0;
  std::vector<double> principal;
  std::vector<std::string> degrade;
  CLI::Option *focal_opt = nullptr, *alt_opt = nullptr, *rad_opt = nullptr, *format_opt = nullptr;
  CLI::Option *klv_opt = nullptr, *exif_opt = nullptr, *gpmf_opt = nullptr;
};

// Scene, flight path and camera.
void AddFlightOptions(CLI::App* cmd, SynthFlags* f) {
  cmd->add_option("--scene", f->scene, "Scene: building | town | terrain | board | sand")
      ->check(CLI::IsMember({"building", "town", "terrain", "board", "sand"}))
      ->capture_default_str();
  cmd->add_option("--path", f->path, "Flight path: orbit | grid | pass | oblique")
      ->check(CLI::IsMember({"orbit", "grid", "pass", "oblique"}))
      ->capture_default_str();
  cmd->add_option("--frames", f->o.flight.frames, "Number of frames")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--size", f->size, "Image size WIDTHxHEIGHT")->check(kSize)->capture_default_str();
  f->focal_opt = cmd->add_option("--focal", f->focal, "Focal length, pixels (default: 60 deg horizontal FOV)")
                     ->check(CLI::PositiveNumber);
  f->alt_opt = cmd->add_option("--altitude", f->altitude, "Flight altitude, metres (world z; default per scene)");
  f->rad_opt = cmd->add_option("--radius", f->radius,
                               "Orbit radius / grid half-size / pass stand-off, metres (default per scene)")
                   ->check(CLI::PositiveNumber);
  cmd->add_option("--overlap", f->grid_overlap,
                  "Grid: forward,side overlap in percent (e.g. 70,40; default: the "
                  "--radius layout, ~65% side)");
  cmd->add_option("--look-at", f->look_at, "Look-at point X,Y,Z in metres (default: the scene's target)")
      ->check(kList3);
  cmd->add_option("--distortion", f->distortion, "Lens distortion k1,k2,p1,p2 (default none)")->check(kList4);
  cmd->add_option("--principal-offset", f->principal,
                  "Principal point minus the image centre DU,DV, pixels (default 0,0)")
      ->delimiter(',')
      ->expected(2);
}

// Rendering, jitter, output format and the truth written beside the frames.
void AddRenderOptions(CLI::App* cmd, SynthFlags* f) {
  cmd->add_option("--sun-azimuth", f->o.render.sun_azimuth_deg, "Sun azimuth, degrees clockwise from north (+y)")
      ->capture_default_str();
  cmd->add_option("--sun-elevation", f->o.render.sun_elevation_deg, "Sun elevation, degrees")
      ->check(CLI::Range(-89.0, 90.0))
      ->capture_default_str();
  cmd->add_option("--exposure", f->o.render.exposure, "Exposure gain")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--noise", f->o.render.noise_sigma, "Sensor noise sigma, digital numbers")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--supersample", f->o.render.supersample, "Anti-aliasing samples per pixel axis (1-4)")
      ->check(CLI::Range(1, 4))
      ->capture_default_str();
  cmd->add_option("--altitude-swing", f->o.flight.altitude_swing,
                  "Orbit: altitude varies by +- this (metres) twice around the circle")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--jitter", f->o.flight.jitter_deg, "Gimbal attitude jitter, degrees (1 sigma)")
      ->check(CLI::Range(0.0, 19.0))
      ->capture_default_str();
  cmd->add_option("--seed", f->o.flight.seed, "Seed for the flight jitter and sensor noise")->capture_default_str();
  f->format_opt = cmd->add_option("--format", f->format, "Output: png | jpg | mp4 | ts")
                      ->check(CLI::IsMember({"png", "jpg", "mp4", "ts"}))
                      ->capture_default_str();
  cmd->add_option("--fps", f->o.fps, "Frame rate (video and truth.json)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--detail", f->o.detail, "Scene texture resolution multiplier (0-4]")
      ->check(CLI::Range(0.01, 4.0))
      ->capture_default_str();
  cmd->add_option("--truth-points", f->o.truth_points, "Surface points sampled for truth/points3D.txt")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_flag("--depth", f->o.write_depth, "Also write float depth maps to DIR/depth/");
}

// Telemetry embedded in the frames or video, and its noise.
void AddTelemetryOptions(CLI::App* cmd, SynthFlags* f) {
  f->klv_opt = cmd->add_flag("--klv", f->o.klv,
                             "Write flight.ts with a MISB ST 0601 KLV telemetry stream (implies --format ts)");
  f->exif_opt = cmd->add_flag("--exif-gps", f->o.exif_gps,
                              "JPEG frames with EXIF GPS and DJI-style XMP attitude/altitudes (implies --format jpg)");
  f->gpmf_opt = cmd->add_flag("--gpmf", f->o.gpmf,
                              "Write flight.mp4 with a GoPro GPMF track: GPS5 + CORI (implies --format mp4)");
  cmd->add_flag("--gps9", f->o.gpmf_gps9, "With --gpmf: GPS9 fixes instead of GPS5");
  cmd->add_option("--geo-origin", f->geo_origin, "With --klv: WGS84 LAT,LON,ALT of the world origin (ellipsoidal m)")
      ->check(kList3)
      ->capture_default_str();
  cmd->add_option("--gps-noise", f->o.klv_options.gps_noise,
                  "With --klv: GPS position noise, metres (1 sigma per axis)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  cmd->add_option("--attitude-noise", f->o.klv_options.attitude_noise,
                  "With --klv: platform heading/pitch/roll noise, degrees (1 sigma)")
      ->check(CLI::Range(0.0, 30.0))
      ->capture_default_str();
}

synth::SynthOptions ToSynthOptions(const SynthFlags& f) {
  synth::SynthOptions opts = f.o;
  opts.scene = synth::ParseScene(f.scene);
  opts.flight.path = synth::ParseFlightPath(f.path);
  opts.format = synth::ParseOutputFormat(f.format);
  std::sscanf(f.size.c_str(), "%d%*c%d", &opts.width, &opts.height);
  if (f.focal_opt->count()) opts.focal = f.focal;
  for (const auto& spec : f.degrade)
    for (const auto& d : synth::ParseDegradation(spec)) opts.degrade.push_back(d);
  if (f.alt_opt->count()) opts.flight.altitude = f.altitude;
  if (f.rad_opt->count()) opts.flight.radius = f.radius;
  if (!f.distortion.empty()) {
    const auto d = ParseList(f.distortion);
    std::copy(d.begin(), d.end(), opts.distortion.begin());
  }
  if (!f.grid_overlap.empty()) {
    const auto v = ParseList(f.grid_overlap);
    if (v.size() != 2) throw Error("--overlap: expected FORWARD,SIDE in percent, e.g. 70,40");
    opts.flight.grid_overlap = std::make_pair(v[0] / 100, v[1] / 100);
  }
  if (!f.principal.empty()) opts.principal_offset = {f.principal[0], f.principal[1]};
  if (!f.look_at.empty()) {
    const auto p = ParseList(f.look_at);
    opts.flight.look_at = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  if (f.klv_opt->count() || f.exif_opt->count() || f.gpmf_opt->count()) {
    const auto g = ParseList(f.geo_origin);
    opts.klv_options.origin = {g[0], g[1], g[2]};
    // Heights above mean sea level (tags 15, 25) differ from ellipsoidal ones (75, 78) by the geoid there.
    if (std::abs(g[0]) <= 90 && std::abs(g[1]) <= 180) {
      const auto n = geo::GeoidUndulation(g[0], g[1]);
      if (!n) spdlog::warn("synth: PROJ's EGM96 grid (egm96_15.gtx) is missing; KLV heights MSL = ellipsoidal");
      opts.klv_options.geoid_undulation = n.value_or(0.0);
    }
    if (!f.format_opt->count())
      opts.format = f.klv_opt->count()    ? synth::OutputFormat::kTs
                    : f.exif_opt->count() ? synth::OutputFormat::kJpg
                                          : synth::OutputFormat::kMp4;
  }
  opts.output = f.output;
  return opts;
}

void Add(CLI::App& app) {
  auto* cmd = app.add_subcommand("synth", "Render a synthetic flight with exact ground truth");
  cmd->footer(
      "Output in DIR:\n"
      "  frames/flight-000000.png ...   frames (png/jpg), 6-digit index from 0\n"
      "  flight.mp4 | flight.ts         video instead (mp4/ts); frames are named flight-NNNNNN.png in the truth\n"
      "  truth/cameras.txt images.txt points3D.txt   COLMAP text model of the exact cameras (+ sample tracks)\n"
      "  scene.obj scene.mtl *.png      the scene mesh in world metres (z up) with textures\n"
      "  truth.json                     characteristic_length (tallest building, m), bounds, seed, fps, options\n"
      "  depth/flight-NNNNNN.tiff       with --depth: float32 depth maps (camera z, metres; 0 = sky)\n"
      "With --klv, flight.ts carries one MISB ST 0601 packet per frame (noisy GPS / attitude of the truth\n"
      "cameras; frame centre and slant range from the true pose; heights both MSL and ellipsoidal, apart by\n"
      "the EGM96 undulation) and truth.json states geo_origin: the world is the local East-North-Up frame of\n"
      "that point.\n"
      "--exif-gps writes JPEG frames with EXIF GPS (MSL altitude) and DJI-style XMP (gimbal/flight angles,\n"
      "absolute/relative altitude); --gpmf writes flight.mp4 with a GoPro GPMF track (GPS5, or GPS9 with --gps9,\n"
      "one fix per frame, ellipsoidal heights; CORI relative orientations). Same noise options as --klv.\n"
      "A --scene is a fixed world; --seed varies only the flight's jitter and the sensor noise.");
  auto f = std::make_shared<SynthFlags>();
  AddFlightOptions(cmd, f.get());
  AddRenderOptions(cmd, f.get());
  AddTelemetryOptions(cmd, f.get());
  cmd->add_flag("!--no-scene", f->o.write_scene, "Do not write scene.obj and its textures");
  cmd->add_option("--degrade", f->degrade,
                  "Degrade frames so they cannot register automatically: FRAMES:KIND, e.g. 5,6:blur "
                  "(KIND: blur = heavy motion blur, contrast = 1% contrast, blank = texture-less patch); repeatable");
  cmd->add_option("-o,--output", f->output, "Output folder")->required();
  cmd->callback([f] {
    const synth::SynthOptions opts = ToSynthOptions(*f);
    const auto r = synth::RunSynth(opts);
    std::cout << "synth: " << r.frames << " frames of scene '" << synth::SceneName(opts.scene) << "' in "
              << opts.output.string() << " (characteristic length " << r.characteristic_length << " m, "
              << r.truth.points.size() << " truth points)\n";
  });
}

const RegisterCommand reg(50, Add);

}  // namespace
}  // namespace fmv3d::app::cmd_synth
