// The terrain models in board/models/, built into the trailnav binary
// (board/cli/builtin_model.S): one per lidar the simulator drives, trained on
// its simulated terrain, for the bench demo and the offline evaluations.
#pragma once

#include <cstdint>
#include <span>

#include "trailnav/drivers/velodyne/model.hpp"

namespace trailnav::cli {

// The model's bytes; empty for a lidar without one (a VLP-16-HiRes: its
// remissions are not a VLP-16's).
std::span<const std::uint8_t> builtin_terrain_model(velodyne::Model lidar) noexcept;
// The large robot's traversability model (board/models/trav-large.tntrav),
// learnt from the VLP-16 `demo-large` demonstration (docs/traversability.md).
std::span<const std::uint8_t> builtin_traversability_model() noexcept;

}  // namespace trailnav::cli
