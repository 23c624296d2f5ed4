// The check every zero-allocation test ends with: no real-time thread made a
// heap operation after alloc_guard::arm(), each offender named.
#pragma once

#include <gtest/gtest.h>

#include <array>

#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::test {

inline void expect_no_realtime_allocations() {
  std::array<alloc_guard::ThreadAllocations, alloc_guard::kMaxThreadNames> rows{};
  const std::size_t n = alloc_guard::report(rows);
  for (std::size_t i = 0; i < n; ++i) {
    ADD_FAILURE() << "thread '" << rows[i].name << "' made " << rows[i].allocations << " heap operations after arm()";
  }
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
}

}  // namespace trailnav::test
