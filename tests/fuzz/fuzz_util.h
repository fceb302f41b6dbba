// Helpers shared by the libFuzzer targets whose readers take a path: the fuzz input is written to a scratch
// folder private to this process (libFuzzer's -jobs/-fork run several processes), optionally split into several
// files at a separator line, and the reader is called on it.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace fmv3d::fuzz {

// A folder under $TMPDIR (or /tmp) that only this process writes; created on first use.
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    const char* tmp = std::getenv("TMPDIR");
    const std::filesystem::path d =
        std::filesystem::path(tmp && *tmp ? tmp : "/tmp") / ("fmv3d-fuzz-" + std::to_string(getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

inline std::filesystem::path WriteScratch(const std::string& name, const char* data, size_t size) {
  const std::filesystem::path p = ScratchDir() / name;
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(data, static_cast<std::streamsize>(size));
  return p;
}

// Splits the input at lines that read exactly kSplit; missing parts are empty. Seeds for multi-file readers
// (OBJ + MTL, the three COLMAP files) are the files concatenated with this line between them.
inline constexpr const char* kSplit = "%%fmv3d-fuzz-next-file%%\n";

inline std::vector<std::string> SplitInput(const uint8_t* data, size_t size, size_t parts) {
  const std::string all(reinterpret_cast<const char*>(data), size);
  const std::string sep(kSplit);
  std::vector<std::string> out;
  size_t begin = 0;
  while (out.size() + 1 < parts) {
    const size_t at = all.find(sep, begin);
    if (at == std::string::npos) break;
    out.push_back(all.substr(begin, at - begin));
    begin = at + sep.size();
  }
  out.push_back(all.substr(begin));
  out.resize(parts);
  return out;
}

}  // namespace fmv3d::fuzz
