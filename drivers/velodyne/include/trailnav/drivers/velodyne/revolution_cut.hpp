// Splits the stream of firing sequences into revolutions exactly at a chosen
// azimuth, sequence by sequence, so that no packet's firings are shifted into
// the wrong revolution. The cut uses each sequence's firing azimuth (before
// any laser's own rotation correction), so the lasers of one firing always
// stay together. The range-image assembler and `trailnav decode` both cut
// with it.
#pragma once

#include <array>

#include "trailnav/drivers/velodyne/decoder.hpp"

namespace trailnav::velodyne {

class RevolutionCut {
 public:
  explicit RevolutionCut(double cut_azimuth_rad) noexcept;

  // Takes the next decoded packet; returns the index of its first firing
  // sequence past the cut, or info.sequences when it does not cross it (nor
  // for the very first packet's first sequence).
  int first_new_sequence(const PacketInfo& info) noexcept;

  // Of the packet last taken: sequence s's azimuth after the cut, in
  // hundredths of a degree, [0, 36000).
  float relative(int s) const noexcept { return relative_[static_cast<std::size_t>(s)]; }
  // The same for the last sequence of the packet before it; negative before
  // the second packet.
  float previous_relative() const noexcept { return previous_before_; }
  // The newest sequence's azimuth after the cut; negative before any packet.
  float last_relative() const noexcept { return last_; }

 private:
  float cut_;  // hundredths of a degree
  std::array<float, kMaxSequencesPerPacket> relative_{};
  float last_ = -1.0f;            // last sequence seen
  float previous_before_ = -1.0f; // last sequence before the packet last taken
};

}  // namespace trailnav::velodyne
