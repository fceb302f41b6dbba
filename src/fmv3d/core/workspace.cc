#include "fmv3d/core/workspace.h"

#include "fmv3d/core/error.h"

namespace fmv3d::core {

void Workspace::Require(const std::filesystem::path& input, const char* producing_command) const {
  if (!std::filesystem::exists(input))
    throw Error(root_.string() + ": " + std::filesystem::relative(input, root_).string() + " is missing; run `fmv3d " +
                producing_command + "` first");
}

bool Workspace::UpToDate(const std::vector<std::filesystem::path>& outputs,
                         const std::vector<std::filesystem::path>& inputs) {
  namespace fs = std::filesystem;
  fs::file_time_type oldest_output = fs::file_time_type::max();
  for (const auto& o : outputs) {
    std::error_code ec;
    const auto t = fs::last_write_time(o, ec);
    if (ec) return false;
    oldest_output = std::min(oldest_output, t);
  }
  for (const auto& i : inputs) {
    std::error_code ec;
    const auto t = fs::last_write_time(i, ec);
    if (ec || t > oldest_output) return false;
  }
  return true;
}

}  // namespace fmv3d::core
