// The solver's storage is runtime's Arena (trailnav/runtime/arena.hpp),
// named here as the pose-graph code has always named it.
#pragma once

#include "trailnav/runtime/arena.hpp"

namespace trailnav::slam {
using trailnav::Arena;
using trailnav::ArenaResource;
}  // namespace trailnav::slam
