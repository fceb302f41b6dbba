#include "fmv3d/telemetry/av_demux.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/avutil.h>
}

#include <spdlog/spdlog.h>

#include <vector>

#include "fmv3d/core/error.h"
#include "fmv3d/telemetry/av_error.h"

namespace fmv3d::telemetry {

bool DemuxPackets(const std::filesystem::path& path, const std::function<bool(const AVStream&)>& wanted,
                  const std::function<void(const DemuxedPacket&)>& on_packet, const DemuxOptions& options) {
  // libavformat warns on every asynchronous KLV stream ("start time ... is not set"); keep stderr for errors.
  if (av_log_get_level() > AV_LOG_ERROR) av_log_set_level(AV_LOG_ERROR);
  AVFormatContext* fmt = nullptr;
  int err = avformat_open_input(&fmt, path.c_str(), nullptr, nullptr);
  if (err < 0) throw Error(path.string() + ": cannot open: " + AvError(err));
  struct Closer {
    AVFormatContext** f;
    ~Closer() { avformat_close_input(f); }
  } closer{&fmt};
  err = avformat_find_stream_info(fmt, nullptr);
  if (err < 0) throw Error(path.string() + ": cannot read stream info: " + AvError(err));

  std::vector<bool> is_wanted(fmt->nb_streams, false), is_read(fmt->nb_streams, false);
  bool any = false;
  for (unsigned i = 0; i < fmt->nb_streams; ++i) {
    is_wanted[i] = wanted(*fmt->streams[i]);
    any = any || is_wanted[i];
  }
  if (!any) return false;
  for (unsigned i = 0; i < fmt->nb_streams; ++i) {
    const bool timing = options.with_video_timing && fmt->streams[i]->codecpar->codec_type == AVMEDIA_TYPE_VIDEO;
    is_read[i] = is_wanted[i] || timing;
    fmt->streams[i]->discard = is_read[i] ? AVDISCARD_DEFAULT : AVDISCARD_ALL;
  }

  const double start = fmt->start_time != AV_NOPTS_VALUE ? fmt->start_time / double(AV_TIME_BASE) : 0.0;
  AVPacket* pkt = av_packet_alloc();
  if (!pkt) throw Error(path.string() + ": out of memory");
  struct PacketFree {
    AVPacket** p;
    ~PacketFree() { av_packet_free(p); }
  } packet_free{&pkt};
  while ((err = av_read_frame(fmt, pkt)) >= 0) {
    if (!is_read[pkt->stream_index]) {  // some demuxers still hand over a discarded stream's packets
      av_packet_unref(pkt);
      continue;
    }
    const AVStream* s = fmt->streams[pkt->stream_index];
    DemuxedPacket p;
    p.stream_index = pkt->stream_index;
    p.wanted = is_wanted[pkt->stream_index];
    p.data = pkt->data;
    p.size = pkt->size > 0 ? static_cast<size_t>(pkt->size) : 0;
    const int64_t ts = pkt->pts != AV_NOPTS_VALUE ? pkt->pts : pkt->dts;
    if (ts != AV_NOPTS_VALUE) p.time = ts * av_q2d(s->time_base) - start;
    p.duration = pkt->duration > 0 ? pkt->duration * av_q2d(s->time_base) : 0.0;
    on_packet(p);  // should it throw, av_packet_free unreferences the packet
    av_packet_unref(pkt);
  }
  if (err != AVERROR_EOF) spdlog::warn("{}: demuxing stopped early: {}", path.string(), AvError(err));
  return true;
}

}  // namespace fmv3d::telemetry
