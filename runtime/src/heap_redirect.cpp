#include "trailnav/runtime/heap_redirect.hpp"

namespace trailnav::heap_redirect {

bool supported() noexcept {
  Redirect* previous = nullptr;
  if (!detail::exchange(nullptr, &previous)) return false;
  Redirect* ignored = nullptr;
  detail::exchange(previous, &ignored);
  return true;
}

Scope::Scope(Redirect& redirect) noexcept { active_ = detail::exchange(&redirect, &previous_); }

Scope::~Scope() {
  if (!active_) return;
  Redirect* ignored = nullptr;
  detail::exchange(previous_, &ignored);
}

}  // namespace trailnav::heap_redirect
