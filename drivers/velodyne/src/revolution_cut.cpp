#include "trailnav/drivers/velodyne/revolution_cut.hpp"

#include <numbers>

namespace trailnav::velodyne {
namespace {

constexpr float kTurn = 36000.0f;  // hundredths of a degree

}  // namespace

RevolutionCut::RevolutionCut(double cut_azimuth_rad) noexcept
    : cut_(static_cast<float>(cut_azimuth_rad * 18000.0 / std::numbers::pi)) {}

int RevolutionCut::first_new_sequence(const PacketInfo& info) noexcept {
  previous_before_ = last_;
  int first_new = info.sequences;
  for (int s = 0; s < info.sequences; ++s) {
    float r = info.sequence_azimuth[static_cast<std::size_t>(s)] - cut_;
    if (r < 0.0f) r += kTurn;
    if (r >= kTurn) r -= kTurn;
    relative_[static_cast<std::size_t>(s)] = r;
    // A drop of more than half a turn is the wrap past the cut.
    if (first_new == info.sequences && last_ >= 0.0f && r + kTurn / 2 < last_) first_new = s;
    last_ = r;
  }
  return first_new;
}

}  // namespace trailnav::velodyne
