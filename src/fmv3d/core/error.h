// fmv3d::Error: the one exception type for problems a user can act on (bad input, missing file, a stage that
// cannot proceed). The CLI prints its message as one line on stderr and exits 1; nothing else should abort.
#pragma once

#include <stdexcept>
#include <string>

namespace fmv3d {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace fmv3d
