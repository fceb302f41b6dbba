#include "fmv3d/core/files.h"

#include <unistd.h>

#include <fstream>
#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::core {

void WriteAtomically(const fs::path& path, const std::function<void(const fs::path& tmp)>& write) {
  if (path.has_parent_path()) EnsureDirectory(path.parent_path());
  const fs::path tmp = path.parent_path() / ("." + path.stem().string() + ".tmp" + std::to_string(getpid()) +
                                             path.extension().string());
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw Error(path.string() + ": cannot write (" + ec.message() + ")");
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

void WriteTextFile(const fs::path& path, const std::string& text) {
  WriteAtomically(path, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.close();
    if (!out) throw Error(path.string() + ": write failed");
  });
}

std::string ReadTextFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void WriteJson(const fs::path& path, const nlohmann::json& j) { WriteTextFile(path, j.dump(2) + "\n"); }

nlohmann::json ReadJson(const fs::path& path) {
  const std::string text = ReadTextFile(path);
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path.string() + ": not valid JSON (" + e.what() + ")");
  }
}

void EnsureDirectory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error(dir.string() + ": cannot create directory (" + ec.message() + ")");
}

}  // namespace fmv3d::core
