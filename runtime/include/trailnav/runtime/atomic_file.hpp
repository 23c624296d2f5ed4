// A file that is replaced whole or not at all: the new bytes go to a
// temporary file beside it, are flushed to the disk (fsync), renamed over
// the target, and the directory is flushed so that the rename itself
// survives a power cut. A reader — or the next start after a crash — sees
// the old file or the new one, never a mix. The paths are fixed at
// construction (the only allocation); write() is two system calls' worth of
// work and never touches the heap, so a thread the allocation guard watches
// may call it.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace trailnav {

class AtomicFile {
 public:
  explicit AtomicFile(std::string path);

  // 0 when the file now holds `bytes`, else the errno of the step that
  // failed (the target is then unchanged and the temporary file removed).
  int write(std::span<const std::uint8_t> bytes) const noexcept;

  const std::string& path() const noexcept { return path_; }
  const std::string& temporary() const noexcept { return tmp_; }

 private:
  std::string path_, tmp_, dir_;
};

// The whole of a file into `bytes` (for the file formats' loaders): 0, or the
// errno of what failed (the bytes are then empty). Allocates; not for
// real-time threads.
int read_whole_file(const std::string& path, std::vector<std::uint8_t>& bytes);

}  // namespace trailnav
