// Heap redirect where the project does not own malloc (sanitizer builds, the
// fuzzers): a scope does nothing and the heap serves every allocation.
#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::heap_redirect::detail {
bool exchange(Redirect*, Redirect** previous) noexcept {
  *previous = nullptr;
  return false;
}
}  // namespace trailnav::heap_redirect::detail
