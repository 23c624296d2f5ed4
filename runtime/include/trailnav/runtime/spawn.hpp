// Starting another program: trailnavd from `trailnav demo`, and trailnavd or
// `trailnav` from the tests. Not for real-time threads (it allocates and
// forks); the one place that knows posix_spawn's file actions.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace trailnav {

struct SpawnOptions {
  // Where the child's standard output and error go: a file (created or
  // truncated), "/dev/null", or "" to share the caller's.
  std::string stdout_path;
  std::string stderr_path;
};

// Starts args[0] (a path) with args; the child's pid, or -1 with `error`
// naming the program and the reason.
pid_t spawn_process(const std::vector<std::string>& args, const SpawnOptions& options, std::string& error);

}  // namespace trailnav
