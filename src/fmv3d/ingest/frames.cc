#include "fmv3d/ingest/frames.h"

#include <signal.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <exception>
#include <map>
#include <set>
#include <tuple>

#include "fmv3d/core/error.h"
#include "fmv3d/core/files.h"
#include "fmv3d/core/logging.h"
#include "fmv3d/ingest/video_reader.h"
#include "fmv3d/telemetry/dji_srt.h"
#include "fmv3d/telemetry/gpmf_telemetry.h"
#include "fmv3d/telemetry/telemetry.h"

namespace fmv3d::ingest {
namespace fs = std::filesystem;

namespace {

std::string LowerExt(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

// Removes the staging folder unless released (the stage failed half-way).
struct StagingGuard {
  fs::path dir;
  bool released = false;
  ~StagingGuard() {
    if (!released) {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  }
};

// Frame names must be unique inside frames/: a clash (same file name in two folders, same video stem) gets
// the parent folder's name as a prefix, then a counter.
class NameRegistry {
 public:
  std::string Unique(const fs::path& source, const std::string& stem) {
    std::string s = stem;
    if (used_.count(s)) {
      const std::string parent = source.parent_path().filename().string();
      if (!parent.empty()) s = parent + "-" + stem;
      for (int k = 2; used_.count(s); ++k) s = stem + "-" + std::to_string(k);
      spdlog::warn("{}: name '{}' is already taken by another input; using '{}'", source.string(), stem, s);
    }
    used_.insert(s);
    return s;
  }

 private:
  std::set<std::string> used_;
};

struct ImageCameraKey {
  int w, h;
  std::string make, model;
  long focal_centi_mm;
  bool operator<(const ImageCameraKey& o) const {
    return std::tie(w, h, make, model, focal_centi_mm) < std::tie(o.w, o.h, o.make, o.model, o.focal_centi_mm);
  }
};

}  // namespace

core::Camera GuessPrior(int width, int height) {
  return core::Camera::Pinhole(width, height, 1.2 * std::max(width, height));
}

void IngestOptions::Check() const {
  if (workspace.empty()) throw Error("frames: no workspace folder given (-o WS)");
  if (max_frames < 0) throw Error("frames: --max-frames must be >= 0");
  keyframes.Check();
  telemetry.fix.Check();
}

std::vector<fs::path> ExpandInputs(const std::vector<fs::path>& inputs) {
  std::vector<fs::path> files;
  for (const auto& in : inputs) {
    std::error_code ec;
    if (fs::is_directory(in, ec)) {
      std::vector<fs::path> found;
      for (const auto& e : fs::directory_iterator(in, ec)) {
        if (!e.is_regular_file()) continue;
        if (io::HasImageExtension(e.path()) || io::HasVideoExtension(e.path())) found.push_back(e.path());
      }
      if (ec) throw Error(in.string() + ": cannot list folder (" + ec.message() + ")");
      if (found.empty()) throw Error(in.string() + ": folder holds no images or videos (sub-folders are not searched)");
      std::sort(found.begin(), found.end());
      files.insert(files.end(), found.begin(), found.end());
    } else if (fs::exists(in, ec)) {
      files.push_back(in);
    } else {
      throw Error(in.string() + ": no such file or folder");
    }
  }
  if (files.empty()) throw Error("frames: no input given");
  return files;
}

namespace {
// With no better prior than the guess, the telemetry's horizontal field of view (KLV sensor HFOV) of the camera's
// frames gives the focal: f = (w / 2) / tan(HFOV / 2) — the median over frames. The mapper then skips its focal
// scan and refines this value. Zoom during the video changes the HFOV; one camera per video keeps one focal,
// so that is only warned about.
void FocalFromTelemetryHfov(const io::FramesIndex& index, uint32_t camera_id, core::Camera* cam,
                            io::PriorSource* source) {
  std::vector<double> hfov;
  for (const auto& f : index.frames)
    if (f.camera_id == camera_id && f.telemetry && f.telemetry->horizontal_fov) {
      const double h = *f.telemetry->horizontal_fov;
      if (h > 0.01 && h < 170) hfov.push_back(h);
    }
  if (hfov.empty()) return;
  std::sort(hfov.begin(), hfov.end());
  const double median = hfov[hfov.size() / 2];
  if (hfov.back() > 1.05 * hfov.front())
    spdlog::warn(
        "camera {}: the telemetry HFOV changes from {:.3f}° to {:.3f}° (zoom); the focal prior uses the "
        "median, {:.3f}°",
        camera_id, hfov.front(), hfov.back(), median);
  cam->f = 0.5 * cam->width / std::tan(0.5 * median * M_PI / 180) / cam->aspect;  // the horizontal focal is f · aspect
  *source = {io::PriorKind::kTelemetryHfov, ""};
}

// A video's own telemetry: KLV data streams (MISB ST 0601 / EG0104), a GoPro GPMF track, or a DJI .SRT beside
// it. Telemetry is an optional extra: a damaged stream costs a warning, never the frames.
std::vector<telemetry::TelemetrySample> LoadTelemetry(const std::filesystem::path& video,
                                                      const telemetry::FixQualityOptions& fix) {
  std::vector<telemetry::TelemetrySample> samples;
  try {
    telemetry::TelemetryStats stats;
    samples = telemetry::ReadVideoTelemetry(video, &stats);
    if (stats.klv.bad_checksum + stats.klv.malformed > 0)
      spdlog::warn("{}: {} malformed KLV packets skipped", video.string(),
                   stats.klv.bad_checksum + stats.klv.malformed);
    if (!samples.empty()) {
      spdlog::info("{}: {} KLV telemetry samples", video.string(), samples.size());
      return samples;
    }
    const telemetry::GpmfTelemetry g = telemetry::ReadGpmfTelemetry(video, fix);
    if (g.parse.malformed > 0) spdlog::warn("{}: {} malformed GPMF entries skipped", video.string(), g.parse.malformed);
    if (g.fixes.Rejected() > 0)
      spdlog::warn("{}: {}; frames there get no position", video.string(), g.fixes.Summary("GPMF GPS fixes"));
    if (!g.samples.empty()) {
      spdlog::info("{}: {} GPMF telemetry samples from {} payloads", video.string(), g.samples.size(), g.payloads);
      return g.samples;
    }
    if (auto srt = telemetry::FindDjiSrtBeside(video)) {
      samples = telemetry::ReadDjiSrt(*srt);
      spdlog::info("{}: {} telemetry samples from {}", video.string(), samples.size(), srt->string());
    }
  } catch (const Error& e) {
    spdlog::warn("{}: telemetry ignored ({})", video.string(), e.what());
  }
  return samples;
}
}  // namespace

namespace {

// Metadata of a still image, read in parallel before the frames are added in input order.
struct ImageMeta {
  int width = 0, height = 0;
  io::ExifInfo exif;
  double sharpness = 0;
};

// Size, EXIF and sharpness of every image among `files` (entries of other files stay empty). Rethrows the
// first bad file in input order.
std::vector<ImageMeta> ReadImageMetadata(const std::vector<fs::path>& files) {
  std::vector<ImageMeta> meta(files.size());
  std::vector<size_t> images;
  for (size_t i = 0; i < files.size(); ++i)
    if (io::HasImageExtension(files[i])) images.push_back(i);
  std::vector<std::exception_ptr> errors(files.size());
  if (!images.empty()) {
    core::Progress progress("read images", images.size());
    tbb::parallel_for(size_t(0), images.size(), [&](size_t k) {
      const size_t i = images[k];
      try {
        const cv::Mat img = ReadInputImage(files[i]);
        meta[i] = {img.cols, img.rows, io::ReadExif(files[i]), Sharpness(img)};
      } catch (...) {
        errors[i] = std::current_exception();
      }
      progress.Add();
    });
  }
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
  return meta;
}

// Builds the frames index in a staging folder: photos are copied (GIF converted to PNG), videos decoded into
// keyframes, telemetry attached to each frame; then cameras are given their priors.
class FramesBuilder {
 public:
  FramesBuilder(const IngestOptions& options, const fs::path& staging) : options_(options), staging_(staging) {}

  void AddPhoto(const fs::path& file, const ImageMeta& m) {
    const io::ExifInfo& exif = m.exif;
    const ImageCameraKey key{m.width, m.height, exif.make, exif.model, std::lround(exif.focal_mm * 100)};
    auto it = image_cameras_.find(key);
    uint32_t cam_id;
    if (it == image_cameras_.end()) {
      CameraGroup g;
      g.width = m.width;
      g.height = m.height;
      g.source = file.parent_path().string();
      g.exif = exif;
      cam_id = AddCamera(g);
      image_cameras_[key] = cam_id;
    } else {
      cam_id = it->second;
    }
    const bool convert = LowerExt(file) == ".gif";
    const std::string stem = names_.Unique(file, file.stem().string());
    const std::string name = stem + (convert ? std::string(".png") : file.extension().string());
    if (convert) {
      io::WriteImage(staging_ / name, ReadInputImage(file));
    } else {
      std::error_code ec;
      fs::copy_file(file, staging_ / name, fs::copy_options::overwrite_existing, ec);
      if (ec) throw Error(file.string() + ": cannot copy into the workspace (" + ec.message() + ")");
    }
    io::FrameRecord r;
    r.name = name;
    r.camera_id = cam_id;
    r.source = file.string();
    r.sharpness = m.sharpness;
    const telemetry::PhotoTelemetry t = telemetry::TelemetryFromPhoto(exif, options_.telemetry);
    photo_fixes_.Add(t.rejection);
    if (exif.damaged) ++damaged_exif_;
    r.telemetry = t.sample;
    if (t.dji.malformed > 0)
      spdlog::warn("{}: {} DJI XMP fields are not numbers (ignored)", file.string(), t.dji.malformed);
    index_.frames.push_back(r);
  }

  // A video (or an unknown extension, which FFmpeg gets to try): its keyframes.
  void AddVideo(const fs::path& file) {
    std::unique_ptr<VideoReader> reader;
    try {
      reader = std::make_unique<VideoReader>(file);
    } catch (const Error& e) {
      if (io::HasVideoExtension(file)) throw;
      throw Error(file.string() + ": unsupported or unreadable file (neither an image nor a video FFmpeg can read)");
    }
    const VideoInfo& info = reader->info();
    CameraGroup g;
    g.width = info.width;
    g.height = info.height;
    g.source = file.string();
    g.is_video = true;
    g.pixel_aspect = info.pixel_aspect;
    const uint32_t cam_id = AddCamera(g);
    const std::string stem = names_.Unique(file, file.stem().string());
    KeyframeSelector selector(options_.keyframes, info.fps);
    spdlog::info("{}: {}x{} {} {:.2f} fps, ~{} frames; keyframe gap {}..{} frames", file.string(), info.width,
                 info.height, info.codec, info.fps, info.frame_count_hint, selector.min_gap(), selector.max_gap());
    if (info.interlaced)
      spdlog::warn("{}: interlaced video; frames are used as decoded (no deinterlacing), fast motion will comb",
                   file.string());
    const std::vector<telemetry::TelemetrySample> samples = LoadTelemetry(file, options_.telemetry.fix);
    if (!samples.empty()) tracks_.push_back({file.string(), samples});
    core::Progress progress("decode " + stem, static_cast<size_t>(std::max<int64_t>(info.frame_count_hint, 0)));
    std::vector<Keyframe> kept;
    tbb::task_group writers;
    int in_flight = 0;
    auto flush = [&] {
      for (const Keyframe& k : kept) {
        char idx[32];
        std::snprintf(idx, sizeof(idx), "%06lld", static_cast<long long>(k.index));
        io::FrameRecord r;
        r.name = stem + "-" + idx + ".png";
        r.camera_id = cam_id;
        r.source = file.string();
        r.frame_index = k.index;
        r.timestamp = k.timestamp;
        r.sharpness = k.sharpness;
        r.telemetry = telemetry::InterpolateTelemetry(samples, k.timestamp);
        // PNG encoding costs more than decoding: it runs beside the decoder, at most 4 frames in flight.
        if (++in_flight > 4) {
          writers.wait();
          in_flight = 1;
        }
        writers.run([path = staging_ / r.name, image = k.image] { io::WriteImage(path, image); });
        index_.frames.push_back(r);
      }
      kept.clear();
    };
    VideoFrame frame;
    size_t n_video_frames = 0;
    const size_t first = index_.frames.size();
    while (reader->Read(&frame)) {
      selector.Push(frame, &kept);
      flush();
      progress.Add();
      ++n_video_frames;
    }
    selector.Finish(&kept);
    flush();
    writers.wait();  // rethrows a write error
    progress.Finish();
    if (reader->frames_read() == 0)
      throw Error(file.string() + ": no decodable video frame" +
                  (reader->warning().empty() ? std::string() : " (" + reader->warning() + ")"));
    spdlog::info("{}: {} frames decoded, {} blurred, {} keyframes", file.string(), n_video_frames,
                 selector.blurred_frames(), index_.frames.size() - first);
  }

  // After every input: --max-frames, unused cameras dropped, priors; frames.json and telemetry.json written.
  io::FramesIndex Finish() {
    if (damaged_exif_ > 0)
      spdlog::warn("{} photos have an EXIF block that cannot be read; they carry no position or focal from it",
                   damaged_exif_);
    if (photo_fixes_.Rejected() > 0)
      spdlog::warn("{}; those photos carry no telemetry", photo_fixes_.Summary("photo GPS fixes"));
    if (photo_fixes_.kept > 0) spdlog::info("{} photos with a GPS position", photo_fixes_.kept);
    if (options_.max_frames > 0 && static_cast<int>(index_.frames.size()) > options_.max_frames) Subsample();
    DropUnusedCameras();
    SetIntrinsicsPriors();
    io::WriteFramesIndex(index_, staging_ / "frames.json");
    if (!tracks_.empty()) telemetry::WriteTelemetryTracks(tracks_, staging_ / "telemetry.json");
    return std::move(index_);
  }

 private:
  uint32_t AddCamera(CameraGroup g) {
    io::CameraPrior c;
    c.camera = GuessPrior(g.width, g.height);
    c.camera.id = static_cast<uint32_t>(index_.cameras.size() + 1);
    c.prior_source = {io::PriorKind::kGuess, ""};
    c.source = g.source;
    index_.cameras.push_back(c);
    groups_.push_back(std::move(g));
    return index_.cameras.back().camera.id;
  }

  // --max-frames: an even subsample of everything kept.
  void Subsample() {
    const size_t n = index_.frames.size(), m = static_cast<size_t>(options_.max_frames);
    std::vector<io::FrameRecord> chosen;
    std::vector<bool> keep(n, false);
    for (size_t i = 0; i < m; ++i) {
      const size_t j = m == 1 ? 0 : static_cast<size_t>(std::llround(double(i) * (n - 1) / (m - 1)));
      keep[j] = true;
    }
    for (size_t i = 0; i < n; ++i) {
      if (keep[i]) {
        chosen.push_back(index_.frames[i]);
      } else {
        std::error_code ec;
        fs::remove(staging_ / index_.frames[i].name, ec);
      }
    }
    spdlog::info("--max-frames {}: kept {} of {} frames", options_.max_frames, chosen.size(), n);
    index_.frames = std::move(chosen);
  }

  // Cameras no frame refers to any more are dropped and the ids renumbered 1..n.
  void DropUnusedCameras() {
    std::vector<uint32_t> remap(index_.cameras.size() + 1, 0);
    for (const auto& f : index_.frames) remap[f.camera_id] = 1;
    std::vector<io::CameraPrior> cams;
    std::vector<CameraGroup> grps;
    for (size_t i = 0; i < index_.cameras.size(); ++i) {
      if (!remap[i + 1]) continue;
      remap[i + 1] = static_cast<uint32_t>(cams.size() + 1);
      cams.push_back(index_.cameras[i]);
      cams.back().camera.id = remap[i + 1];
      grps.push_back(groups_[i]);
    }
    for (auto& f : index_.frames) f.camera_id = remap[f.camera_id];
    index_.cameras = std::move(cams);
    groups_ = std::move(grps);
  }

  void SetIntrinsicsPriors() {
    for (size_t i = 0; i < index_.cameras.size(); ++i) {
      io::PriorSource source{io::PriorKind::kGuess, ""};
      core::Camera cam =
          options_.prior ? options_.prior(groups_[i], &source) : GuessPrior(groups_[i].width, groups_[i].height);
      cam.id = index_.cameras[i].camera.id;
      if (cam.width != groups_[i].width || cam.height != groups_[i].height)
        throw Error(groups_[i].source + ": intrinsics prior has the wrong image size");
      // Non-square pixels (e.g. DV/SD video, SAR 10:11): a pixel is pixel_aspect times wider than tall, so the
      // horizontal focal in pixels is f / pixel_aspect. A calibration already measured it.
      if (groups_[i].pixel_aspect != 1.0 && source.kind != io::PriorKind::kCalibration)
        cam.aspect /= groups_[i].pixel_aspect;
      if (source.kind == io::PriorKind::kGuess)
        FocalFromTelemetryHfov(index_, static_cast<uint32_t>(i + 1), &cam, &source);
      cam.Validate();
      index_.cameras[i].camera = cam;
      index_.cameras[i].prior_source = source;
    }
    for (const auto& c : index_.cameras)
      spdlog::info("camera {}: {}x{} f={:.1f} ({}) from {}", c.camera.id, c.camera.width, c.camera.height, c.camera.f,
                   io::PriorSourceName(c.prior_source), c.source);
  }

  const IngestOptions& options_;
  const fs::path staging_;
  io::FramesIndex index_;
  std::vector<CameraGroup> groups_;  // parallel to index_.cameras
  std::map<ImageCameraKey, uint32_t> image_cameras_;
  NameRegistry names_;
  std::vector<telemetry::TelemetryTrack> tracks_;  // every video's whole telemetry → frames/telemetry.json
  size_t damaged_exif_ = 0;                        // photos whose EXIF block cannot be read
  telemetry::FixCounts photo_fixes_;               // photos with a position: kept / dropped
};

// Swaps the complete staging folder in place of frames/ (the old one restored when that fails).
void ReplaceFramesFolder(const fs::path& workspace, StagingGuard* staging) {
  const fs::path frames_dir = workspace / "frames";
  std::error_code ec;
  const fs::path old = workspace / (".frames-old-" + std::to_string(getpid()));
  if (fs::exists(frames_dir, ec)) {
    fs::rename(frames_dir, old, ec);
    if (ec) throw Error(frames_dir.string() + ": cannot replace (" + ec.message() + ")");
  }
  fs::rename(staging->dir, frames_dir, ec);
  if (ec) {
    std::error_code ec2;
    if (fs::exists(old, ec2)) fs::rename(old, frames_dir, ec2);
    throw Error(frames_dir.string() + ": cannot write (" + ec.message() + ")");
  }
  staging->released = true;
  fs::remove_all(old, ec);
}

// Removes the staging and old frames folders a killed run left behind (named by the process id that made them;
// those of a process still alive are kept).
void RemoveStaleStaging(const fs::path& workspace) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(workspace, ec)) {
    const std::string name = e.path().filename().string();
    for (const std::string prefix : {".frames-staging-", ".frames-old-"}) {
      if (name.rfind(prefix, 0) != 0) continue;
      const std::string digits = name.substr(prefix.size());
      if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) continue;
      const pid_t pid = static_cast<pid_t>(std::stol(digits));
      if (pid == getpid() || !(kill(pid, 0) != 0 && errno == ESRCH)) continue;
      std::error_code rm;
      fs::remove_all(e.path(), rm);
    }
  }
}

}  // namespace

io::FramesIndex IngestFrames(const std::vector<fs::path>& inputs, const IngestOptions& options) {
  options.Check();
  const std::vector<fs::path> files = ExpandInputs(inputs);
  core::EnsureDirectory(options.workspace);
  RemoveStaleStaging(options.workspace);
  StagingGuard staging{options.workspace / (".frames-staging-" + std::to_string(getpid()))};
  {
    std::error_code ec;
    fs::remove_all(staging.dir, ec);
  }
  core::EnsureDirectory(staging.dir);

  const std::vector<ImageMeta> meta = ReadImageMetadata(files);
  FramesBuilder builder(options, staging.dir);
  for (size_t i = 0; i < files.size(); ++i) {
    if (io::HasImageExtension(files[i]))
      builder.AddPhoto(files[i], meta[i]);
    else
      builder.AddVideo(files[i]);
  }
  io::FramesIndex index = builder.Finish();
  ReplaceFramesFolder(options.workspace, &staging);
  spdlog::info("{}: {} frames, {} cameras", (options.workspace / "frames").string(), index.frames.size(),
               index.cameras.size());
  return index;
}

}  // namespace fmv3d::ingest
