// Runs `trailnav` (TRAILNAV_BINARY, defined by the test's CMake target) with
// arguments, quoting each, and returns its exit status with everything it
// printed (stdout and stderr) in `out`. For the command-line tests.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace trailnav::test {

inline int run_cli(const std::vector<std::string>& args, std::string& out) {
  const std::filesystem::path log =
      std::filesystem::temp_directory_path() / ("trailnav-cli-" + std::to_string(::getpid()) + ".log");
  std::string cmd = TRAILNAV_BINARY;
  for (const std::string& a : args) cmd += " '" + a + "'";
  cmd += " > " + log.string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  std::ifstream in(log);
  out.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  std::filesystem::remove(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace trailnav::test
