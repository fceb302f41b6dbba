// The one place that opens a media container for its telemetry: the KLV and GPMF readers differ only in which
// data streams they want and what they do with a packet's bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>

struct AVStream;

namespace fmv3d::telemetry {

struct DemuxedPacket {
  int stream_index = 0;
  bool wanted = false;  // from a stream `wanted` chose; false: a video packet read for its time only
  const uint8_t* data = nullptr;
  size_t size = 0;
  std::optional<double> time;  // seconds from the container's start (pts, else dts); none when the packet has neither
  double duration = 0;         // seconds; 0 when the container does not say
};

struct DemuxOptions {
  // Also hand over the video streams' packets (not decoded): data packets without a time borrow theirs.
  bool with_video_timing = false;
};

// Opens path and reads, in file order, the packets of the streams `wanted` accepts; the data of a packet lives
// only for the call. Returns false, without reading, when no stream is wanted. Throws core's Error when the file
// cannot be opened or probed; a demuxing error part-way is logged and ends the read (what came before is kept).
bool DemuxPackets(const std::filesystem::path& path, const std::function<bool(const AVStream&)>& wanted,
                  const std::function<void(const DemuxedPacket&)>& on_packet, const DemuxOptions& options = {});

}  // namespace fmv3d::telemetry
