// Child processes without a shell: fork + execv of an argv list, stdin from /dev/null, stdout and stderr
// appended to a log file, every other descriptor closed (the server's sockets must not leak into a job), in its
// own process group.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace fmv3d::server {

// Throws fmv3d::Error when the log cannot be opened or fork fails. An exec failure shows as exit code 127.
pid_t SpawnProcess(const std::vector<std::string>& argv, const std::filesystem::path& log);

// Non-blocking wait: the exit code (128 + signal when killed) once the child has ended, else nullopt.
std::optional<int> PollExit(pid_t pid);

}  // namespace fmv3d::server
