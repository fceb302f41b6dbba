// Video encoding with FFmpeg (libavformat/libavcodec): BGR frames → H.264 (libx264) in MP4 or MPEG-TS,
// yuv420p. The container follows the extension (.mp4, .ts, .mkv). When libx264 is missing, it falls back to
// MPEG-4 part 2 (mp4/mkv) or MPEG-2 (ts). Encoding is single-threaded with bit-exact flags, so the same
// frames give a byte-identical file. yuv420p needs even width and height (an odd size is an error).
// With `klv_stream`, an MPEG-TS also gets a SMPTE KLV data stream (STANAG 4609 style, KLVA): WriteKlv
// puts one metadata packet at a frame's presentation time. With `gpmf_stream`, an MP4/MOV gets a GoPro GPMF
// data track (codec tag 'gpmd', as GoPro cameras write it): WriteGpmf puts one payload spanning some frames.
#pragma once

#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace fmv3d::ingest {

struct VideoWriterOptions {
  double fps = 25;
  int crf = 18;  // x264 quality (lower = better); other codecs get a matching bit rate
  int gop = 25;  // key-frame interval, frames
  std::string preset = "medium";
  bool klv_stream = false;   // add a KLV data stream, packets stamped with frame PTS (MPEG-TS only)
  bool gpmf_stream = false;  // add a GPMF 'gpmd' data track (MP4/MOV only)
  void Check() const;
};

class VideoWriter {
 public:
  VideoWriter(const std::filesystem::path& path, int width, int height, const VideoWriterOptions& options = {});
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  // bgr: CV_8UC3 of the writer's size.
  void Write(const cv::Mat& bgr);
  // One KLV packet (whole key-length-value bytes) stamped with the presentation time of frame
  // `frame_index` (0-based, as counted by Write). Needs options.klv_stream; indices must not decrease.
  void WriteKlv(const std::vector<uint8_t>& bytes, int64_t frame_index);
  // One GPMF payload covering `frames` frames from `first_frame` (its pts and duration). Needs
  // options.gpmf_stream; payloads must come in frame order.
  void WriteGpmf(const std::vector<uint8_t>& bytes, int64_t first_frame, int64_t frames);
  // Flushes the encoder and finishes the file (also done by the destructor, which swallows errors).
  void Close();
  const std::string& codec_name() const;
  int frames_written() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fmv3d::ingest
