// Decode memory and speed: streams a long video through ingest::VideoReader (and the keyframe selector, as
// `fmv3d frames` does) and reports the peak resident set size (VmHWM) — the issue's "10-minute 1080p video
// stays under 1 GiB RSS".
//
// The video is $FMV3D_DECODE_BENCH_VIDEO, default /tmp/fmv3d-decode-bench-1080p.mp4, made once with
//   ffmpeg -f lavfi -i testsrc2=size=1920x1080:rate=30 -t 600 -c:v libx264 -preset ultrafast \
//          -pix_fmt yuv420p /tmp/fmv3d-decode-bench-1080p.mp4
// (the benchmark skips with a message when it is absent). Run: build/decode_bench
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "fmv3d/ingest/keyframes.h"
#include "fmv3d/ingest/video_reader.h"

namespace {

std::string VideoPath() {
  const char* env = std::getenv("FMV3D_DECODE_BENCH_VIDEO");
  return env ? env : "/tmp/fmv3d-decode-bench-1080p.mp4";
}

// Peak resident set size of this process in MiB (Linux /proc/self/status VmHWM).
double PeakRssMiB() {
  std::ifstream in("/proc/self/status");
  std::string key;
  while (in >> key) {
    if (key == "VmHWM:") {
      double kb = 0;
      in >> kb;
      return kb / 1024.0;
    }
    std::getline(in, key);
  }
  return -1;
}

void Decode(benchmark::State& state, bool select_keyframes) {
  const std::string path = VideoPath();
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(("no benchmark video " + path + " (see the comment in decode_bench.cc)").c_str());
    return;
  }
  int64_t frames = 0, keyframes = 0;
  for (auto _ : state) {
    fmv3d::ingest::VideoReader reader(path);
    fmv3d::ingest::KeyframeSelector selector(fmv3d::ingest::KeyframeOptions(), reader.info().fps);
    fmv3d::ingest::VideoFrame frame;
    std::vector<fmv3d::ingest::Keyframe> kept;
    while (reader.Read(&frame)) {
      ++frames;
      if (select_keyframes) {
        selector.Push(frame, &kept);
        keyframes += static_cast<int64_t>(kept.size());
        kept.clear();  // ingestion writes them out at once
      }
    }
    state.counters["width"] = reader.info().width;
    state.counters["height"] = reader.info().height;
  }
  state.counters["frames"] = static_cast<double>(frames);
  state.counters["keyframes"] = static_cast<double>(keyframes);
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
  state.counters["peak_rss_MiB"] = PeakRssMiB();
}

void BM_Decode(benchmark::State& state) { Decode(state, false); }
void BM_DecodeAndSelectKeyframes(benchmark::State& state) { Decode(state, true); }

BENCHMARK(BM_Decode)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();
BENCHMARK(BM_DecodeAndSelectKeyframes)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
