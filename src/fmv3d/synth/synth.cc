#include "fmv3d/synth/synth.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "fmv3d/core/camera_json.h"
#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/ingest/video_writer.h"
#include "fmv3d/io/colmap_model.h"
#include "fmv3d/io/exif_writer.h"
#include "fmv3d/io/obj_io.h"
#include "fmv3d/synth/noise.h"

namespace fmv3d::synth {
namespace fs = std::filesystem;

void SynthOptions::Check() const {
  flight.Check();
  render.Check();
  for (const auto& d : degrade)
    if (d.frame < 0 || d.frame >= flight.frames)
      throw Error(fmt::format("synth: --degrade frame {} is not one of the {} frames (0..{})", d.frame, flight.frames,
                              flight.frames - 1));
  if (width <= 0 || height <= 0 || width > 16384 || height > 16384)
    throw Error(fmt::format("synth: bad image size {}x{}", width, height));
  if (focal && !(*focal > 0)) throw Error("synth: focal length must be positive");
  for (double d : distortion)
    if (!std::isfinite(d) || std::abs(d) > 10) throw Error("synth: distortion coefficients must be finite, |k| <= 10");
  for (int k = 0; k < 2; ++k)
    if (!std::isfinite(principal_offset[k]) || std::abs(principal_offset[k]) >= 0.5 * (k ? height : width))
      throw Error("synth: the principal point offset must keep the principal point inside the image");
  if (IsVideo() && (width % 2 || height % 2))
    throw Error(fmt::format("synth: video needs an even width and height, got {}x{} (use png/jpg)", width, height));
  if (jpeg_quality < 1 || jpeg_quality > 100) throw Error("synth: jpeg quality must be 1..100");
  if (!(fps > 0 && fps <= 1000)) throw Error("synth: fps must be in (0, 1000]");
  if (!(detail > 0 && detail <= 4)) throw Error("synth: detail must be in (0, 4]");
  if (truth_points < 0) throw Error("synth: truth points must be >= 0");
  if (output.empty()) throw Error("synth: an output folder is required");
  const std::string got = std::string(" (got '") + OutputFormatName(format) + "')";
  if (klv && format != OutputFormat::kTs) throw Error("synth: --klv writes an MPEG-TS: use --format ts" + got);
  if (exif_gps && format != OutputFormat::kJpg)
    throw Error("synth: --exif-gps writes JPEG frames: use --format jpg" + got);
  if (gpmf && format != OutputFormat::kMp4) throw Error("synth: --gpmf writes an MP4: use --format mp4" + got);
  if (HasTelemetry()) klv_options.Check();
}

nlohmann::json SynthOptions::ToJson() const {
  nlohmann::json j;
  j["scene"] = SceneName(scene);
  j["path"] = FlightPathName(flight.path);
  j["frames"] = flight.frames;
  if (!degrade.empty()) {
    j["degrade"] = nlohmann::json::array();
    for (const auto& d : degrade) j["degrade"].push_back({{"frame", d.frame}, {"kind", DegradationName(d.kind)}});
  }
  j["size"] = {width, height};
  if (focal) j["focal"] = *focal;
  if (flight.altitude) j["altitude"] = *flight.altitude;
  if (flight.radius) j["radius"] = *flight.radius;
  if (flight.grid_overlap) j["grid_overlap"] = {flight.grid_overlap->first, flight.grid_overlap->second};
  if (flight.look_at) j["look_at"] = {flight.look_at->x(), flight.look_at->y(), flight.look_at->z()};
  j["jitter_deg"] = flight.jitter_deg;
  j["position_jitter"] = flight.position_jitter;
  j["seed"] = flight.seed;
  j["distortion"] = distortion;
  j["principal_offset"] = principal_offset;
  j["sun_azimuth"] = render.sun_azimuth_deg;
  j["sun_elevation"] = render.sun_elevation_deg;
  j["ambient"] = render.ambient;
  j["exposure"] = render.exposure;
  j["noise"] = render.noise_sigma;
  j["supersample"] = render.supersample;
  j["format"] = OutputFormatName(format);
  j["jpeg_quality"] = jpeg_quality;
  j["fps"] = fps;
  j["detail"] = detail;
  j["truth_points"] = truth_points;
  j["write_depth"] = write_depth;
  j["klv"] = klv;
  if (exif_gps) j["exif_gps"] = true;
  if (gpmf) j["gpmf"] = gpmf_gps9 ? "GPS9" : "GPS5";
  if (HasTelemetry()) {
    j["geo_origin"] = {
        {"lat", klv_options.origin.lat}, {"lon", klv_options.origin.lon}, {"alt", klv_options.origin.alt}};
    j["gps_noise"] = klv_options.gps_noise;
    j["attitude_noise"] = klv_options.attitude_noise;
  }
  return j;
}

core::Camera SynthCamera(const SynthOptions& o) {
  const double f = o.focal ? *o.focal : 0.5 * o.width / std::tan(M_PI / 6);  // 60° horizontal FOV
  core::Camera c = core::Camera::Pinhole(o.width, o.height, f);
  c.k1 = o.distortion[0];
  c.k2 = o.distortion[1];
  c.p1 = o.distortion[2];
  c.p2 = o.distortion[3];
  c.u0 += o.principal_offset[0];
  c.v0 += o.principal_offset[1];
  c.Validate();
  return c;
}

const char* OutputFormatName(OutputFormat format) {
  switch (format) {
    case OutputFormat::kPng:
      return "png";
    case OutputFormat::kJpg:
      return "jpg";
    case OutputFormat::kMp4:
      return "mp4";
    case OutputFormat::kTs:
      return "ts";
  }
  return "png";
}

OutputFormat ParseOutputFormat(const std::string& name) {
  for (OutputFormat f : {OutputFormat::kPng, OutputFormat::kJpg, OutputFormat::kMp4, OutputFormat::kTs})
    if (name == OutputFormatName(f)) return f;
  throw Error("synth: unknown format '" + name + "' (expected png, jpg, mp4 or ts)");
}

std::string FrameName(int index, const std::string& ext) { return fmt::format("flight-{:06d}.{}", index, ext); }

namespace {

// Area-weighted random surface points (fixed per scene, independent of the flight seed).
std::vector<Eigen::Vector3d> SampleSurface(const io::TexturedMesh& mesh, int n) {
  std::vector<double> cum(mesh.faces.size());
  double total = 0;
  for (size_t i = 0; i < mesh.faces.size(); ++i) {
    const auto& f = mesh.faces[i];
    if (f.material >= 0 && mesh.materials[f.material].name == "far_ground") {
      cum[i] = total;  // only the modelled area carries truth points
      continue;
    }
    total +=
        0.5 *
        (mesh.vertices[f.v[1]] - mesh.vertices[f.v[0]]).cross(mesh.vertices[f.v[2]] - mesh.vertices[f.v[0]]).norm();
    cum[i] = total;
  }
  std::vector<Eigen::Vector3d> pts;
  std::mt19937_64 rng(20240611);
  auto uni = [&] { return static_cast<double>(rng() >> 11) / 9007199254740992.0; };
  for (int k = 0; k < n && total > 0; ++k) {
    const size_t i = std::lower_bound(cum.begin(), cum.end(), uni() * total) - cum.begin();
    const auto& f = mesh.faces[std::min(i, cum.size() - 1)];
    double a = uni(), b = uni();
    if (a + b > 1) a = 1 - a, b = 1 - b;
    pts.push_back(mesh.vertices[f.v[0]] + a * (mesh.vertices[f.v[1]] - mesh.vertices[f.v[0]]) +
                  b * (mesh.vertices[f.v[2]] - mesh.vertices[f.v[0]]));
  }
  return pts;
}

// One still frame as PNG or JPEG; with EXIF/XMP GPS when the flight asks for photos with metadata.
void WriteStill(const cv::Mat& image, const fs::path& path, const SynthOptions& o, const core::Camera& camera,
                const telemetry::klv::St0601Record* record) {
  std::vector<int> params;
  if (o.format == OutputFormat::kJpg)
    params = {cv::IMWRITE_JPEG_QUALITY, o.jpeg_quality};
  else
    params = {cv::IMWRITE_PNG_COMPRESSION, 3};
  if (o.exif_gps) {
    std::vector<uint8_t> jpeg;
    if (!cv::imencode(".jpg", image, jpeg, params)) throw Error(path.string() + ": cannot encode frame");
    const PhotoMetadata meta = MakePhotoMetadata(*record, camera, o.klv_options);
    const std::vector<uint8_t> bytes = io::InsertJpegMetadata(jpeg, io::EncodeTiffExif(meta.exif), meta.xmp);
    core::WriteAtomically(path, [&](const fs::path& tmp) {
      std::ofstream out(tmp, std::ios::binary);
      out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      if (!out) throw Error(path.string() + ": cannot write frame");
    });
  } else {
    core::WriteAtomically(path, [&](const fs::path& tmp) {
      if (!cv::imwrite(tmp.string(), image, params)) throw Error(path.string() + ": cannot write frame");
    });
  }
}

// Ground-truth observations of one frame: sampled points whose projection lands on the surface they lie on.
void AddTrueObservations(const std::vector<Eigen::Vector3d>& samples, const core::Camera& camera,
                         const core::Pose& pose, const render::RenderResult& frame, const SynthOptions& o,
                         core::Image* image, std::vector<std::vector<core::TrackElement>>* tracks,
                         std::vector<Eigen::Matrix<uint8_t, 3, 1>>* colours) {
  core::Image& img = *image;
  for (size_t p = 0; p < samples.size(); ++p) {
    const Eigen::Vector3d xc = pose.Transform(samples[p]);
    if (xc.z() <= o.render.near_plane) continue;
    const Eigen::Vector2d uv = camera.Project(xc);
    if (!camera.InImage(uv, 0.5)) continue;
    const int col = static_cast<int>(uv.x()), row = static_cast<int>(uv.y());
    if (col < 0 || row < 0 || col >= o.width || row >= o.height) continue;
    const float d = frame.depth.at<float>(row, col);
    if (!(d > 0) || std::abs(d - xc.z()) > 0.01 * xc.z() + 0.05) continue;
    (*tracks)[p].push_back({img.id, static_cast<uint32_t>(img.points2d.size())});
    img.points2d.push_back(uv);
    img.point3d_ids.push_back(core::kNoPoint3D);
    if ((*tracks)[p].size() == 1) {
      const cv::Vec3b c = frame.image.at<cv::Vec3b>(row, col);
      (*colours)[p] << c[2], c[1], c[0];
    }
  }
}

// Samples seen by two frames or more become the truth's 3D points; the others stay untriangulated 2D points.
void AddTruthPoints(const std::vector<Eigen::Vector3d>& samples,
                    const std::vector<std::vector<core::TrackElement>>& tracks,
                    const std::vector<Eigen::Matrix<uint8_t, 3, 1>>& colours, core::Reconstruction* truth) {
  core::Reconstruction& rec = *truth;
  uint64_t next_id = 1;
  for (size_t p = 0; p < samples.size(); ++p) {
    if (tracks[p].size() < 2) continue;
    core::Point3D pt;
    pt.id = next_id++;
    pt.xyz = samples[p];
    pt.rgb = colours[p];
    pt.error = 0;
    pt.track = tracks[p];
    for (const auto& te : pt.track) rec.images[te.image_id].point3d_ids[te.point2d_idx] = static_cast<int64_t>(pt.id);
    rec.points[pt.id] = std::move(pt);
  }
}

nlohmann::json TruthJson(const Scene& scene, const SynthOptions& o, const FlightGeometry& geo,
                         const core::Camera& camera, int frames, size_t truth_points, const fs::path& video_path) {
  const auto box = scene.Bounds();
  const auto world_box = scene.mesh.Bounds();
  nlohmann::json j;
  j["scene"] = scene.name;
  j["characteristic_length"] = scene.characteristic_length;
  j["bounds"] = {{"min", {box.min().x(), box.min().y(), box.min().z()}},
                 {"max", {box.max().x(), box.max().y(), box.max().z()}}};
  j["world_bounds"] = {{"min", {world_box.min().x(), world_box.min().y(), world_box.min().z()}},
                       {"max", {world_box.max().x(), world_box.max().y(), world_box.max().z()}}};
  j["seed"] = o.flight.seed;
  j["fps"] = o.fps;
  j["frames"] = frames;
  j["format"] = OutputFormatName(o.format);
  j["video"] = o.IsVideo() ? video_path.filename().string() : "";
  j["frame_names"] = std::string("flight-NNNNNN.") + (o.format == OutputFormat::kJpg ? "jpg" : "png") +
                     " (6 digits, from 0 in decode order)";
  j["camera"] = core::CameraToJson(camera);
  j["flight"] = {{"path", FlightPathName(o.flight.path)},
                 {"altitude", geo.altitude},
                 {"radius", geo.radius},
                 {"look_at", {geo.look_at.x(), geo.look_at.y(), geo.look_at.z()}}};
  j["world"] = "metres, z up, ground around z = 0; poses world-to-camera (x_cam = R X + t)";
  j["depth"] = "camera-frame z along the optical axis, metres; 0 = nothing";
  j["truth_points"] = truth_points;
  j["buildings"] = nlohmann::json::array();
  for (const auto& b : scene.buildings)
    j["buildings"].push_back({{"name", b.name},
                              {"base", {b.base.x(), b.base.y(), b.base.z()}},
                              {"width", b.width},
                              {"depth", b.depth},
                              {"eave_height", b.eave_height},
                              {"ridge_height", b.ridge_height},
                              {"heading_deg", b.heading_deg}});
  if (o.HasTelemetry()) {
    const GeoPoint& g = o.klv_options.origin;
    j["geo_origin"] = {{"lat", g.lat}, {"lon", g.lon}, {"alt", g.alt}};
    j["geo_frame"] = "world x = east, y = north, z = up (metres) at geo_origin; alt = WGS84 ellipsoidal height";
    j["geoid_undulation_m"] = o.klv_options.geoid_undulation;  // KLV heights MSL = ellipsoidal − this
  }
  j["options"] = o.ToJson();
  return j;
}

}  // namespace

SynthResult RunSynth(const SynthOptions& o) {
  o.Check();
  const core::Camera camera = SynthCamera(o);
  spdlog::info("synth: building scene '{}'", SceneName(o.scene));
  SceneOptions so;
  so.detail = o.detail;
  const Scene scene = MakeScene(o.scene, so);
  const std::vector<core::Pose> poses = MakeFlight(scene, camera, o.flight);
  const FlightGeometry geo = ResolveFlight(scene, camera, o.flight);
  const render::Renderer renderer(scene.mesh);

  core::EnsureDirectory(o.output);
  const fs::path frames_dir = o.output / "frames", depth_dir = o.output / "depth";
  if (!o.IsVideo()) core::EnsureDirectory(frames_dir);
  if (o.write_depth) core::EnsureDirectory(depth_dir);
  std::unique_ptr<ingest::VideoWriter> video;
  const fs::path video_path = o.output / (std::string("flight.") + OutputFormatName(o.format));
  if (o.IsVideo()) {
    ingest::VideoWriterOptions vo;
    vo.fps = o.fps;
    vo.gop = std::max(1, static_cast<int>(std::lround(o.fps)));
    vo.klv_stream = o.klv;
    vo.gpmf_stream = o.gpmf;
    // Write to a temporary and rename at the end, so an interrupted run leaves no truncated video.
    video = std::make_unique<ingest::VideoWriter>(
        o.output / (std::string("flight.partial.") + OutputFormatName(o.format)), o.width, o.height, vo);
  }

  SynthResult result;
  if (o.HasTelemetry()) {
    KlvTelemetryOptions ko = o.klv_options;
    ko.fps = o.fps;
    ko.seed = o.flight.seed;
    result.klv = MakeKlvTelemetry(poses, camera, 0.0, ko);  // ground plane z = 0 for the frame centre
  }
  core::Reconstruction& rec = result.truth;
  core::Camera cam = camera;
  cam.id = 1;
  rec.cameras[1] = cam;
  const std::vector<Eigen::Vector3d> samples = SampleSurface(scene.mesh, o.truth_points);
  std::vector<std::vector<core::TrackElement>> tracks(samples.size());
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colours(samples.size(), Eigen::Matrix<uint8_t, 3, 1>::Zero());

  core::Progress progress("render", poses.size());
  for (size_t k = 0; k < poses.size(); ++k) {
    render::RenderOptions ro = o.render;
    ro.noise_seed = Hash64(o.flight.seed * 1000003ull + k);
    render::RenderResult frame = renderer.Render(camera, poses[k], ro);
    for (const auto& d : o.degrade)
      if (d.frame == static_cast<int>(k)) Degrade(d.kind, &frame.image);
    if (video) {
      video->Write(frame.image);
      if (o.klv) video->WriteKlv(telemetry::klv::EncodeSt0601Packet(result.klv[k]), static_cast<int64_t>(k));
      // GPMF: one payload per second of frames, written with its first frame.
      const size_t per_payload = static_cast<size_t>(std::max(1L, std::lround(o.fps)));
      if (o.gpmf && k % per_payload == 0) {
        const size_t last = std::min(poses.size(), k + per_payload);
        video->WriteGpmf(
            telemetry::gpmf::EncodePayload(MakeGpmfPayload(result.klv, poses, k, last, o.fps, o.gpmf_gps9)),
            static_cast<int64_t>(k), static_cast<int64_t>(last - k));
      }
    } else {
      WriteStill(frame.image, frames_dir / FrameName(static_cast<int>(k), OutputFormatName(o.format)), o, camera,
                 o.HasTelemetry() ? &result.klv[k] : nullptr);
    }
    if (o.write_depth) {
      const fs::path path = depth_dir / fmt::format("flight-{:06d}.tiff", k);
      core::WriteAtomically(path, [&](const fs::path& tmp) {
        if (!cv::imwrite(tmp.string(), frame.depth)) throw Error(path.string() + ": cannot write depth");
      });
    }
    core::Image img;
    img.id = static_cast<uint32_t>(k + 1);
    img.camera_id = 1;
    img.name = FrameName(static_cast<int>(k),
                         o.format == OutputFormat::kJpg ? "jpg" : "png");  // as the files / extractor name them
    img.pose = poses[k];
    AddTrueObservations(samples, camera, poses[k], frame, o, &img, &tracks, &colours);
    rec.images[img.id] = std::move(img);
    progress.Add();
  }
  progress.Finish();
  if (video) {
    video->Close();
    result.frames = video->frames_written();
    spdlog::info("synth: encoded {} frames with {}", result.frames, video->codec_name());
    video.reset();
    fs::rename(o.output / (std::string("flight.partial.") + OutputFormatName(o.format)), video_path);
  } else {
    result.frames = static_cast<int>(poses.size());
  }
  AddTruthPoints(samples, tracks, colours, &rec);
  rec.Validate();
  io::WriteColmapText(rec, o.output / "truth");
  if (o.write_scene) io::WriteObj(scene.mesh, o.output / "scene.obj");

  const nlohmann::json j = TruthJson(scene, o, geo, camera, result.frames, rec.points.size(), video_path);
  core::WriteJson(o.output / "truth.json", j);
  result.characteristic_length = scene.characteristic_length;
  spdlog::info("synth: {} frames, {} truth points → {}", result.frames, rec.points.size(), o.output.string());
  return result;
}

}  // namespace fmv3d::synth
