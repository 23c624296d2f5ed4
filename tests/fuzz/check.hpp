// An invariant a fuzz target asserts: reports where, then crashes so that
// libFuzzer keeps the input.
#pragma once

#include <cstdio>
#include <cstdlib>

#define check(condition)                                                                        \
  do {                                                                                          \
    if (!(condition)) {                                                                         \
      std::fprintf(stderr, "%s:%d: invariant failed: %s\n", __FILE__, __LINE__, #condition);    \
      std::abort();                                                                             \
    }                                                                                           \
  } while (false)
