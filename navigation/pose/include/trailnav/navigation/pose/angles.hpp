// Angles of the pose code: pi, and wrapping to (-pi, pi].
#pragma once

#include <cmath>

namespace trailnav::pose {

inline constexpr double kPi = 3.14159265358979323846;

// The same direction in [-pi, pi] (constant time for any finite angle).
inline double wrap_angle(double a) noexcept { return std::remainder(a, 2.0 * kPi); }

}  // namespace trailnav::pose
