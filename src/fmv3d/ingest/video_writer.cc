#include "fmv3d/ingest/video_writer.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

#include <spdlog/spdlog.h>

#include <algorithm>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/av_error.h"

namespace fmv3d::ingest {
namespace fs = std::filesystem;

using telemetry::AvError;

void VideoWriterOptions::Check() const {
  if (!(fps > 0 && fps <= 1000)) throw Error("video: fps must be in (0, 1000]");
  if (crf < 0 || crf > 51) throw Error("video: crf must be 0..51");
  if (gop < 1) throw Error("video: gop must be >= 1");
}

struct VideoWriter::Impl {
  fs::path path;
  int width = 0, height = 0;
  AVFormatContext* fmt = nullptr;
  AVCodecContext* enc = nullptr;
  AVStream* stream = nullptr;
  AVStream* klv = nullptr;   // optional KLV data stream
  AVStream* gpmf = nullptr;  // optional GPMF data track
  int64_t last_klv_pts = -1, last_gpmf_pts = -1;
  AVFrame* frame = nullptr;
  AVPacket* pkt = nullptr;
  SwsContext* sws = nullptr;
  std::string codec;
  int64_t next_pts = 0;
  bool closed = false;

  void Fail(const std::string& what, int code) {
    throw Error(path.string() + ": " + what + (code < 0 ? ": " + AvError(code) : std::string()));
  }
  void Drain(bool flush) {
    int ret = avcodec_send_frame(enc, flush ? nullptr : frame);
    if (ret < 0 && !(flush && ret == AVERROR_EOF)) Fail("encoding failed", ret);
    while (true) {
      ret = avcodec_receive_packet(enc, pkt);
      if (ret == AVERROR(EAGAIN) || ret == AVERROR_EOF) break;
      if (ret < 0) Fail("encoding failed", ret);
      av_packet_rescale_ts(pkt, enc->time_base, stream->time_base);
      pkt->stream_index = stream->index;
      ret = av_interleaved_write_frame(fmt, pkt);
      if (ret < 0) Fail("writing failed", ret);
    }
  }
  // One data packet at frame time `pts` (encoder time base) lasting `duration` frames (0: unknown).
  void WriteData(AVStream* st, const std::vector<uint8_t>& bytes, int64_t pts, int64_t duration, int64_t* last,
                 const char* what) {
    if (closed) throw Error(path.string() + ": write after close");
    if (bytes.empty()) throw Error(path.string() + ": empty " + what + " packet");
    if (pts < 0 || pts < *last) throw Error(path.string() + ": " + what + " packets must come in frame order");
    AVPacket* p = av_packet_alloc();
    if (!p) Fail("out of memory", 0);
    int ret = av_new_packet(p, static_cast<int>(bytes.size()));
    if (ret < 0) {
      av_packet_free(&p);
      Fail("out of memory", ret);
    }
    std::copy(bytes.begin(), bytes.end(), p->data);
    p->pts = p->dts = pts;
    p->duration = duration;
    av_packet_rescale_ts(p, enc->time_base, st->time_base);
    p->stream_index = st->index;
    *last = pts;
    ret = av_interleaved_write_frame(fmt, p);
    av_packet_free(&p);
    if (ret < 0) Fail(std::string("writing ") + what + " failed", ret);
  }
  ~Impl() {
    if (sws) sws_freeContext(sws);
    if (frame) av_frame_free(&frame);
    if (pkt) av_packet_free(&pkt);
    if (enc) avcodec_free_context(&enc);
    if (fmt) {
      if (fmt->pb && !(fmt->oformat->flags & AVFMT_NOFILE)) avio_closep(&fmt->pb);
      avformat_free_context(fmt);
    }
  }
};

VideoWriter::VideoWriter(const fs::path& path, int width, int height, const VideoWriterOptions& o)
    : impl_(std::make_unique<Impl>()) {
  o.Check();
  Impl& m = *impl_;
  m.path = path;
  m.width = width;
  m.height = height;
  if (width <= 0 || height <= 0) throw Error(path.string() + ": video size must be positive");
  if (width % 2 || height % 2)
    throw Error(path.string() + ": video frames need an even width and height (yuv420p), got " + std::to_string(width) +
                "x" + std::to_string(height));
  // FFmpeg and x264 chatter (e.g. "using cpu capabilities") would pollute the CLI's stderr.
  if (av_log_get_level() > AV_LOG_ERROR) av_log_set_level(AV_LOG_ERROR);
  int ret = avformat_alloc_output_context2(&m.fmt, nullptr, nullptr, path.string().c_str());
  if (ret < 0 || !m.fmt) m.Fail("unsupported video container (use .mp4 or .ts)", ret);
  m.fmt->flags |= AVFMT_FLAG_BITEXACT;
  const bool ts = std::string(m.fmt->oformat->name) == "mpegts";
  const AVCodec* codec = avcodec_find_encoder_by_name("libx264");
  if (!codec) codec = avcodec_find_encoder(ts ? AV_CODEC_ID_MPEG2VIDEO : AV_CODEC_ID_MPEG4);
  if (!codec) m.Fail("no H.264, MPEG-4 or MPEG-2 encoder in this FFmpeg", 0);
  m.codec = codec->name;
  m.stream = avformat_new_stream(m.fmt, nullptr);
  m.enc = avcodec_alloc_context3(codec);
  if (!m.stream || !m.enc) m.Fail("out of memory", 0);
  const AVRational rate = av_d2q(o.fps, 100000);
  m.enc->width = width;
  m.enc->height = height;
  m.enc->pix_fmt = AV_PIX_FMT_YUV420P;
  m.enc->time_base = av_inv_q(rate);
  m.enc->framerate = rate;
  m.enc->gop_size = o.gop;
  m.enc->thread_count = 1;  // deterministic output
  m.enc->flags |= AV_CODEC_FLAG_BITEXACT;
  if (m.fmt->oformat->flags & AVFMT_GLOBALHEADER) m.enc->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  AVDictionary* opts = nullptr;
  if (m.codec == "libx264") {
    av_dict_set(&opts, "preset", o.preset.c_str(), 0);
    av_dict_set(&opts, "crf", std::to_string(o.crf).c_str(), 0);
    av_dict_set(&opts, "threads", "1", 0);
  } else {
    m.enc->bit_rate = static_cast<int64_t>(width) * height * o.fps * 0.25 * (52 - o.crf) / 34;
    m.enc->max_b_frames = 2;
  }
  ret = avcodec_open2(m.enc, codec, &opts);
  av_dict_free(&opts);
  if (ret < 0) m.Fail(std::string("cannot open encoder ") + codec->name, ret);
  ret = avcodec_parameters_from_context(m.stream->codecpar, m.enc);
  if (ret < 0) m.Fail("cannot set stream parameters", ret);
  m.stream->time_base = m.enc->time_base;
  m.stream->avg_frame_rate = rate;
  if (o.klv_stream) {
    if (!ts) throw Error(path.string() + ": a KLV data stream needs an MPEG-TS container (.ts)");
    m.klv = avformat_new_stream(m.fmt, nullptr);
    if (!m.klv) m.Fail("out of memory", 0);
    m.klv->codecpar->codec_type = AVMEDIA_TYPE_DATA;
    m.klv->codecpar->codec_id = AV_CODEC_ID_SMPTE_KLV;
    // Asynchronous carriage (stream type 0x06, no ISO 13818-1 metadata AU cell header), but every PES still has
    // the frame's PTS. (FFmpeg 5.1's muxer writes synchronous 0x15 streams without the AU cell header that
    // its own demuxer then strips, cutting 5 bytes off every packet.)
    m.klv->codecpar->profile = FF_PROFILE_KLVA_ASYNC;
    m.klv->time_base = m.enc->time_base;
  }
  if (o.gpmf_stream) {
    const std::string name = m.fmt->oformat->name;
    if (name.find("mp4") == std::string::npos && name.find("mov") == std::string::npos)
      throw Error(path.string() + ": a GPMF track needs an MP4 or MOV container (.mp4)");
    m.gpmf = avformat_new_stream(m.fmt, nullptr);
    if (!m.gpmf) m.Fail("out of memory", 0);
    m.gpmf->codecpar->codec_type = AVMEDIA_TYPE_DATA;
    m.gpmf->codecpar->codec_id = AV_CODEC_ID_BIN_DATA;
    m.gpmf->codecpar->codec_tag = MKTAG('g', 'p', 'm', 'd');
    m.gpmf->time_base = AVRational{1, 1000};  // as GoPro writes it
  }
  if (!(m.fmt->oformat->flags & AVFMT_NOFILE)) {
    ret = avio_open(&m.fmt->pb, path.string().c_str(), AVIO_FLAG_WRITE);
    if (ret < 0) m.Fail("cannot create file", ret);
  }
  ret = avformat_write_header(m.fmt, nullptr);
  if (ret < 0) m.Fail("cannot write header", ret);
  m.frame = av_frame_alloc();
  m.pkt = av_packet_alloc();
  m.frame->format = AV_PIX_FMT_YUV420P;
  m.frame->width = width;
  m.frame->height = height;
  ret = av_frame_get_buffer(m.frame, 0);
  if (ret < 0) m.Fail("cannot allocate a frame", ret);
  m.sws = sws_getContext(width, height, AV_PIX_FMT_BGR24, width, height, AV_PIX_FMT_YUV420P,
                         SWS_BICUBIC | SWS_ACCURATE_RND | SWS_BITEXACT, nullptr, nullptr, nullptr);
  if (!m.sws) m.Fail("cannot create the colour converter", 0);
}

VideoWriter::~VideoWriter() {
  try {
    Close();
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
  }
}

void VideoWriter::Write(const cv::Mat& bgr) {
  Impl& m = *impl_;
  if (m.closed) throw Error(m.path.string() + ": write after close");
  if (bgr.type() != CV_8UC3 || bgr.cols != m.width || bgr.rows != m.height)
    throw Error(m.path.string() + ": frame must be " + std::to_string(m.width) + "x" + std::to_string(m.height) +
                " BGR");
  int ret = av_frame_make_writable(m.frame);
  if (ret < 0) m.Fail("frame not writable", ret);
  const cv::Mat cont = bgr.isContinuous() ? bgr : bgr.clone();
  const uint8_t* src[1] = {cont.data};
  const int stride[1] = {static_cast<int>(cont.step[0])};
  sws_scale(m.sws, src, stride, 0, m.height, m.frame->data, m.frame->linesize);
  m.frame->pts = m.next_pts++;
  m.Drain(false);
}

void VideoWriter::WriteKlv(const std::vector<uint8_t>& bytes, int64_t frame_index) {
  Impl& m = *impl_;
  if (!m.klv) throw Error(m.path.string() + ": no KLV stream (set VideoWriterOptions::klv_stream)");
  m.WriteData(m.klv, bytes, frame_index, 0, &m.last_klv_pts, "KLV");
}

void VideoWriter::WriteGpmf(const std::vector<uint8_t>& bytes, int64_t first_frame, int64_t frames) {
  Impl& m = *impl_;
  if (!m.gpmf) throw Error(m.path.string() + ": no GPMF track (set VideoWriterOptions::gpmf_stream)");
  if (frames < 1) throw Error(m.path.string() + ": a GPMF payload must span at least one frame");
  m.WriteData(m.gpmf, bytes, first_frame, frames, &m.last_gpmf_pts, "GPMF");
}

void VideoWriter::Close() {
  Impl& m = *impl_;
  if (m.closed || !m.fmt) return;
  m.closed = true;
  m.Drain(true);
  const int ret = av_write_trailer(m.fmt);
  if (ret < 0) m.Fail("cannot finish the file", ret);
  if (m.fmt->pb && !(m.fmt->oformat->flags & AVFMT_NOFILE)) avio_closep(&m.fmt->pb);
}

const std::string& VideoWriter::codec_name() const { return impl_->codec; }
int VideoWriter::frames_written() const { return static_cast<int>(impl_->next_pts); }

}  // namespace fmv3d::ingest
