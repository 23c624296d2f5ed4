// W floats or int32s side by side as GCC's vector types, for loops that do
// the same to several points at once (one instruction a lane group where
// the CPU has the width: SSE2 4, AVX2 8; a function compiled for AVX2 must
// hold the 8-wide ones, others split them). W = 1 is a plain value in the
// same clothes, so one template gives the tail of a loop too.
// (GCC ignores a vector_size that depends on a template parameter: one
// specialisation per width.)
#pragma once

#include <cstdint>

namespace trailnav {

template <int W>
struct Lanes;
template <>
struct Lanes<1> {
  using F = float __attribute__((vector_size(4)));
  using I = std::int32_t __attribute__((vector_size(4)));
};
template <>
struct Lanes<4> {
  using F = float __attribute__((vector_size(16)));
  using I = std::int32_t __attribute__((vector_size(16)));
};
template <>
struct Lanes<8> {
  using F = float __attribute__((vector_size(32)));
  using I = std::int32_t __attribute__((vector_size(32)));
};

// Whether this CPU runs AVX2 (asked once): the eight-wide functions are
// called only where it does.
inline bool cpu_has_avx2() noexcept {
#if defined(__GNUC__) && defined(__x86_64__)
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
#else
  return false;
#endif
}

}  // namespace trailnav
