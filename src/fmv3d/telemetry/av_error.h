// FFmpeg's text for one of its error codes, for messages: shared by the demuxers that read telemetry and by
// ingest's video reader and writer.
#pragma once

extern "C" {
#include <libavutil/error.h>
}

#include <string>

namespace fmv3d::telemetry {

inline std::string AvError(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof(buf));
  return buf;
}

}  // namespace fmv3d::telemetry
