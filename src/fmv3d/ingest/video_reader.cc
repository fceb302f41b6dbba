#include "fmv3d/ingest/video_reader.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libavutil/log.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdarg>
#include <mutex>

#include "fmv3d/core/error.h"
#include "fmv3d/io/image_io.h"
#include "fmv3d/telemetry/av_error.h"

namespace fmv3d::ingest {
namespace {

using telemetry::AvError;

// FFmpeg logs straight to stderr by default; route its messages to spdlog's debug level so that a damaged
// stream does not flood the terminal (we report damage once, with the file name, as a warning).
void AvLogToSpdlog(void* avcl, int level, const char* fmt, va_list vl) {
  if (level > AV_LOG_WARNING || !spdlog::should_log(spdlog::level::debug)) return;
  char line[1024];
  int print_prefix = 1;
  av_log_format_line(avcl, level, fmt, vl, line, sizeof(line), &print_prefix);
  std::string s(line);
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
  spdlog::debug("ffmpeg: {}", s);
}

void InstallAvLog() {
  static std::once_flag once;
  std::call_once(once, [] { av_log_set_callback(AvLogToSpdlog); });
}

}  // namespace

struct VideoReader::Impl {
  std::filesystem::path path;
  VideoInfo info;
  AVFormatContext* fmt = nullptr;
  AVCodecContext* dec = nullptr;
  AVPacket* pkt = nullptr;
  AVPacket* held = nullptr;  // the next packet to send (see Feed)
  bool held_valid = false;
  AVFrame* frame = nullptr;
  SwsContext* sws = nullptr;
  int stream = -1;
  AVRational time_base{0, 1};
  double start_seconds = 0;
  int64_t next_index = 0;
  double last_timestamp = -1;
  bool flushing = false;  // no more packets: the decoder is being drained
  bool done = false;
  bool warned = false;
  bool duration_is_video = false;
  std::string warning;

  ~Impl() {
    sws_freeContext(sws);
    av_frame_free(&frame);
    av_packet_free(&pkt);
    av_packet_free(&held);
    avcodec_free_context(&dec);
    if (fmt) avformat_close_input(&fmt);
  }

  [[noreturn]] void Fail(const std::string& what) const { throw Error(path.string() + ": " + what); }

  void Open() {
    InstallAvLog();
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) Fail("no such file");
    int rc = avformat_open_input(&fmt, path.c_str(), nullptr, nullptr);
    if (rc < 0) Fail("not a readable video (" + AvError(rc) + ")");
    rc = avformat_find_stream_info(fmt, nullptr);
    if (rc < 0) Fail("cannot read stream information (" + AvError(rc) + ")");
    const AVCodec* codec = nullptr;
    stream = av_find_best_stream(fmt, AVMEDIA_TYPE_VIDEO, -1, -1, &codec, 0);
    if (stream < 0) Fail("no video stream");
    if (!codec) Fail("no decoder for the video stream");
    AVStream* st = fmt->streams[stream];
    // Only the chosen video stream is demuxed; audio and data (KLV) packets are dropped at the demuxer.
    for (unsigned i = 0; i < fmt->nb_streams; ++i)
      if (static_cast<int>(i) != stream) fmt->streams[i]->discard = AVDISCARD_ALL;
    dec = avcodec_alloc_context3(codec);
    if (!dec) Fail("out of memory");
    if (avcodec_parameters_to_context(dec, st->codecpar) < 0) Fail("bad codec parameters");
    dec->thread_count = 0;  // FFmpeg picks by core count
    dec->thread_type = FF_THREAD_FRAME | FF_THREAD_SLICE;
    rc = avcodec_open2(dec, codec, nullptr);
    if (rc < 0) Fail(std::string("cannot open the ") + codec->name + " decoder (" + AvError(rc) + ")");
    if (dec->width <= 0 || dec->height <= 0) Fail("video stream has no frame size");
    pkt = av_packet_alloc();
    held = av_packet_alloc();
    frame = av_frame_alloc();
    if (!pkt || !held || !frame) Fail("out of memory");

    time_base = st->time_base;
    info.width = dec->width;
    info.height = dec->height;
    info.codec = codec->name;
    const AVRational sar = av_guess_sample_aspect_ratio(fmt, st, nullptr);
    if (sar.num > 0 && sar.den > 0) info.pixel_aspect = av_q2d(sar);
    if (info.pixel_aspect < 0.25 || info.pixel_aspect > 4) info.pixel_aspect = 1;  // nonsense metadata
    info.interlaced =
        st->codecpar->field_order != AV_FIELD_PROGRESSIVE && st->codecpar->field_order != AV_FIELD_UNKNOWN;
    info.container = fmt->iformat ? fmt->iformat->name : "";
    const AVRational fr = st->avg_frame_rate.num > 0 ? st->avg_frame_rate : st->r_frame_rate;
    info.fps = fr.num > 0 && fr.den > 0 ? av_q2d(fr) : 0;
    if (st->duration > 0 && st->duration != AV_NOPTS_VALUE) {
      info.duration = st->duration * av_q2d(st->time_base);
      duration_is_video = true;
    } else if (fmt->duration > 0) {
      info.duration = fmt->duration / static_cast<double>(AV_TIME_BASE);
      // The container's duration covers all streams; it is the video's only when there is no other.
      // MPEG-TS durations are estimated from the bit rate, so they never prove truncation.
      duration_is_video = fmt->nb_streams == 1 && info.container != "mpegts";
    }
    info.frame_count_hint =
        st->nb_frames > 0 ? st->nb_frames : static_cast<int64_t>(std::llround(info.duration * info.fps));
    if (fmt->start_time != AV_NOPTS_VALUE)
      start_seconds = fmt->start_time / static_cast<double>(AV_TIME_BASE);
    else if (st->start_time != AV_NOPTS_VALUE)
      start_seconds = st->start_time * av_q2d(st->time_base);
  }

  void StopFeeding() {
    avcodec_send_packet(dec, nullptr);
    flushing = true;
  }

  // True when the file ends inside the last packet: then that picture is incomplete. MPEG-TS is a sequence
  // of fixed-size packets (188/192/204 bytes), so a cut shows in the file size; other containers store a
  // packet's bytes contiguously at pkt->pos.
  bool TailTruncated(const AVPacket* last) const {
    const int64_t size = fmt->pb ? avio_size(fmt->pb) : -1;
    if (size <= 0) return false;
    if (info.container == "mpegts") {
      int64_t ts_packet = 188;
      if (av_opt_get_int(fmt, "ts_packetsize", AV_OPT_SEARCH_CHILDREN, &ts_packet) < 0 || ts_packet <= 0)
        ts_packet = 188;
      return size % ts_packet != 0;
    }
    return last->pos >= 0 && last->pos + last->size > size;
  }

  // Sends one packet to the decoder; false (with the warning set) when the stream is damaged from here on.
  bool Send(AVPacket* p) {
    const bool corrupt_packet = (p->flags & AV_PKT_FLAG_CORRUPT) != 0;
    const int rc = corrupt_packet ? AVERROR_INVALIDDATA : avcodec_send_packet(dec, p);
    av_packet_unref(p);
    if (rc >= 0) return true;
    // Errors before the first picture are normal for streams cut mid-GOP (TS captures): skip them.
    if (next_index == 0 && !corrupt_packet) return true;
    warning = "corrupt data after frame " + std::to_string(next_index) +
              (corrupt_packet ? std::string(" (truncated packet)") : " (" + AvError(rc) + ")") +
              "; keeping the frames decoded before it";
    return false;
  }

  // Feeds one packet of our stream to the decoder (or starts draining at the end). One packet is held back
  // so that the last one can be checked for truncation before it is decoded.
  void Feed() {
    while (true) {
      const int rc = av_read_frame(fmt, pkt);
      if (rc < 0) {
        if (rc != AVERROR_EOF)
          warning = "read error after frame " + std::to_string(next_index) + " (" + AvError(rc) +
                    "); keeping the frames decoded before it";
        if (held_valid) {
          held_valid = false;
          if (rc == AVERROR_EOF && TailTruncated(held)) {
            warning = "the file ends inside the last picture (truncated); keeping the frames before it";
            av_packet_unref(held);
          } else if (warning.empty()) {
            Send(held);
          } else {
            av_packet_unref(held);
          }
        }
        StopFeeding();
        return;
      }
      if (pkt->stream_index != stream) {
        av_packet_unref(pkt);
        continue;
      }
      if (!held_valid) {
        av_packet_move_ref(held, pkt);
        held_valid = true;
        continue;
      }
      const bool ok = Send(held);
      av_packet_move_ref(held, pkt);
      if (!ok) {
        av_packet_unref(held);
        held_valid = false;
        StopFeeding();
      }
      return;
    }
  }

  bool Read(VideoFrame* out) {
    while (!done) {
      const int rc = avcodec_receive_frame(dec, frame);
      if (rc == AVERROR(EAGAIN)) {
        if (flushing) {  // a decoder that refuses to drain: treat as the end
          done = true;
          break;
        }
        Feed();
        continue;
      }
      if (rc == AVERROR_EOF) {
        done = true;
        break;
      }
      if (rc < 0) {
        warning = "decode error after frame " + std::to_string(next_index) + " (" + AvError(rc) +
                  "); keeping the frames decoded before it";
        done = true;
        break;
      }
      const bool corrupt = (frame->flags & AV_FRAME_FLAG_CORRUPT) || frame->decode_error_flags != 0;
      if (corrupt) {
        av_frame_unref(frame);
        if (next_index == 0 && warning.empty()) continue;  // leading broken references (mid-GOP start)
        if (warning.empty())
          warning =
              "damaged picture after frame " + std::to_string(next_index) + "; keeping the frames decoded before it";
        done = true;
        break;
      }
      Convert(out);
      av_frame_unref(frame);
      return true;
    }
    if (warning.empty() && info.frame_count_hint > 0 && fmt->streams[stream]->nb_frames > 0 &&
        next_index < fmt->streams[stream]->nb_frames)
      warning = "stream ended after " + std::to_string(next_index) + " of " +
                std::to_string(fmt->streams[stream]->nb_frames) + " frames (truncated file?)";
    // Containers that know their length (mkv, mp4 with index) but end early: a partial last packet is
    // silently dropped by some demuxers, so compare the last timestamp with the declared duration.
    if (warning.empty() && next_index > 0 && info.duration > 0 && info.fps > 0 && duration_is_video &&
        last_timestamp + 1.0 / info.fps < info.duration - std::max(0.5, 3.0 / info.fps))
      warning = fmt::format("stream ended at {:.2f} s of {:.2f} s (truncated file?)", last_timestamp, info.duration);
    if (!warning.empty() && next_index > 0 && !warned) {
      warned = true;
      spdlog::warn("{}: {}", path.string(), warning);
    }
    return false;
  }

  void Convert(VideoFrame* out) {
    sws =
        sws_getCachedContext(sws, frame->width, frame->height, static_cast<AVPixelFormat>(frame->format), info.width,
                             info.height, AV_PIX_FMT_BGR24, SWS_BICUBIC | SWS_ACCURATE_RND, nullptr, nullptr, nullptr);
    if (!sws) Fail("cannot convert pixel format " + std::to_string(frame->format));
    out->image.create(info.height, info.width, CV_8UC3);
    uint8_t* dst[4] = {out->image.data, nullptr, nullptr, nullptr};
    int dst_stride[4] = {static_cast<int>(out->image.step[0]), 0, 0, 0};
    sws_scale(sws, frame->data, frame->linesize, 0, frame->height, dst, dst_stride);
    int64_t pts = frame->best_effort_timestamp;
    if (pts == AV_NOPTS_VALUE) pts = frame->pts;
    double t;
    if (pts != AV_NOPTS_VALUE) {
      t = pts * av_q2d(time_base) - start_seconds;
      if (std::abs(t) < 1e-9) t = 0;  // no "-0"
    } else {
      t = last_timestamp < 0 ? 0 : last_timestamp + (info.fps > 0 ? 1.0 / info.fps : 0);
    }
    last_timestamp = t;
    out->index = next_index++;
    out->timestamp = t;
  }
};

VideoReader::VideoReader(const std::filesystem::path& path) : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->Open();
}

VideoReader::~VideoReader() = default;

const VideoInfo& VideoReader::info() const { return impl_->info; }
const std::filesystem::path& VideoReader::path() const { return impl_->path; }
bool VideoReader::Read(VideoFrame* frame) { return impl_->Read(frame); }
const std::string& VideoReader::warning() const { return impl_->warning; }
int64_t VideoReader::frames_read() const { return impl_->next_index; }

bool IsVideo(const std::filesystem::path& path) {
  InstallAvLog();
  AVFormatContext* fmt = nullptr;
  if (avformat_open_input(&fmt, path.c_str(), nullptr, nullptr) < 0) return false;
  bool ok = avformat_find_stream_info(fmt, nullptr) >= 0 &&
            av_find_best_stream(fmt, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0) >= 0;
  avformat_close_input(&fmt);
  return ok;
}

cv::Mat ReadInputImage(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext != ".gif") return io::ReadImage(path);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error(path.string() + ": no such image file");
  // FFmpeg's gif demuxer gives the first frame.
  VideoReader reader(path);
  VideoFrame frame;
  if (!reader.Read(&frame)) throw Error(path.string() + ": no decodable picture in the GIF");
  return frame.image;
}

}  // namespace fmv3d::ingest
