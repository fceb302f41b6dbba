// Streaming video decoder on FFmpeg (libavformat/libavcodec/swscale): any container and codec FFmpeg knows,
// one frame at a time, so a long video never sits in memory. Data streams (e.g. KLV) are ignored here.
//
// Frame index: counted from 0 in the decoder's output order (presentation order, the order a player shows),
// which is what DESIGN.md calls "decode order" for frame names. Timestamp: seconds from the start of the
// container (AVFormatContext::start_time), so that data streams (KLV) of the same file share the clock.
//
// Damage: a truncated or corrupt stream ends the read early; the frames decoded before the damage are
// returned and warning() says what happened. Opening throws fmv3d::Error naming the file when the file is
// unreadable, has no video stream or no decoder.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <string>

namespace fmv3d::ingest {

struct VideoInfo {
  int width = 0, height = 0;
  double pixel_aspect = 1;       // sample aspect ratio (pixel width / pixel height), 1 when unknown
  bool interlaced = false;       // the stream declares interlaced fields (frames are returned as decoded)
  double fps = 0;                // average frame rate (0 when unknown)
  double duration = 0;           // seconds (0 when unknown)
  int64_t frame_count_hint = 0;  // from the container or duration × fps; 0 when unknown; not exact
  std::string codec;             // e.g. "h264"
  std::string container;         // e.g. "mpegts"
};

struct VideoFrame {
  cv::Mat image;         // 8-bit BGR, width × height of the stream
  int64_t index = 0;     // 0-based, in output order
  double timestamp = 0;  // seconds from the container start
};

class VideoReader {
 public:
  // Throws fmv3d::Error ("PATH: ...") when the file cannot be opened as a video.
  explicit VideoReader(const std::filesystem::path& path);
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  const VideoInfo& info() const;
  const std::filesystem::path& path() const;
  // Decodes the next frame into *frame (its image buffer is reused when possible). Returns false at the end
  // of the stream or at the first unrecoverable damage (see warning()).
  bool Read(VideoFrame* frame);
  // Non-empty when the stream ended because of damage (truncation, decode errors).
  const std::string& warning() const;
  int64_t frames_read() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// True when FFmpeg can open the file and it holds a video stream (cheap: probes headers only).
bool IsVideo(const std::filesystem::path& path);

// Any accepted input image (io::HasImageExtension) as 8-bit BGR: io::ReadImage, and GIF (first frame) through
// FFmpeg. Throws fmv3d::Error naming the file when it cannot be read.
cv::Mat ReadInputImage(const std::filesystem::path& path);

}  // namespace fmv3d::ingest
