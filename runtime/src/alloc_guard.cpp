#include "trailnav/runtime/alloc_guard.hpp"

#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <cstring>

namespace trailnav::alloc_guard {
namespace {

struct NameSlot {
  std::atomic<bool> claimed{false};
  std::atomic<bool> ready{false};
  char name[kThreadNameLength] = {};
  std::atomic<std::uint64_t> allocations{0};
};

// Static storage: registering a thread must not allocate either.
NameSlot g_slots[kMaxThreadNames];
NameSlot g_overflow_slot;  // used when more than kMaxThreadNames names exist
std::atomic<bool> g_armed{false};
std::atomic<bool> g_fatal{false};
std::atomic<std::uint64_t> g_total{0};
std::atomic<bool> g_hook_installed{false};

// initial-exec: reading it from inside malloc never allocates TLS lazily.
__attribute__((tls_model("initial-exec"))) thread_local NameSlot* t_slot = nullptr;
__attribute__((tls_model("initial-exec"))) thread_local bool t_reporting = false;

bool same_name(const NameSlot& slot, const char* name) noexcept {
  return std::strncmp(slot.name, name, kThreadNameLength - 1) == 0;
}

NameSlot* find_or_claim(const char* name) noexcept {
  for (NameSlot& slot : g_slots) {
    if (slot.ready.load(std::memory_order_acquire) && same_name(slot, name)) return &slot;
  }
  for (NameSlot& slot : g_slots) {
    bool expected = false;
    if (slot.claimed.compare_exchange_strong(expected, true, std::memory_order_acq_rel)) {
      std::strncpy(slot.name, name, kThreadNameLength - 1);
      slot.ready.store(true, std::memory_order_release);
      return &slot;
    }
  }
  return &g_overflow_slot;
}

void write_stderr(const char* text) noexcept {
  const std::size_t length = std::strlen(text);
  [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, text, length);
}

}  // namespace

void mark_realtime_thread(const char* name) noexcept { t_slot = find_or_claim(name); }
void unmark_current_thread() noexcept { t_slot = nullptr; }
bool current_thread_is_realtime() noexcept { return t_slot != nullptr; }

bool arm() noexcept {
  const bool installed = hook_installed();
  g_armed.store(true, std::memory_order_release);
  return installed;
}
void disarm() noexcept { g_armed.store(false, std::memory_order_release); }
bool armed() noexcept { return g_armed.load(std::memory_order_acquire); }
void set_fatal(bool fatal) noexcept { g_fatal.store(fatal, std::memory_order_release); }

std::uint64_t total_allocations() noexcept { return g_total.load(std::memory_order_acquire); }

std::size_t report(std::span<ThreadAllocations> out) noexcept {
  std::size_t n = 0;
  auto emit = [&](const NameSlot& slot, const char* name) {
    const std::uint64_t count = slot.allocations.load(std::memory_order_acquire);
    if (count == 0 || n >= out.size()) return;
    std::strncpy(out[n].name, name, kThreadNameLength - 1);
    out[n].allocations = count;
    ++n;
  };
  for (const NameSlot& slot : g_slots) {
    if (slot.ready.load(std::memory_order_acquire)) emit(slot, slot.name);
  }
  emit(g_overflow_slot, "(other real-time threads)");
  return n;
}

void reset_counters() noexcept {
  for (NameSlot& slot : g_slots) slot.allocations.store(0, std::memory_order_release);
  g_overflow_slot.allocations.store(0, std::memory_order_release);
  g_total.store(0, std::memory_order_release);
}

bool hook_installed() noexcept {
  if (!g_hook_installed.load(std::memory_order_acquire)) {
    g_hook_installed.store(detail::install_hook(), std::memory_order_release);
  }
  return g_hook_installed.load(std::memory_order_acquire);
}

namespace detail {

void on_heap_operation() noexcept {
  NameSlot* slot = t_slot;
  if (slot == nullptr || t_reporting || !g_armed.load(std::memory_order_relaxed)) return;
  slot->allocations.fetch_add(1, std::memory_order_relaxed);
  g_total.fetch_add(1, std::memory_order_relaxed);
  if (g_fatal.load(std::memory_order_relaxed)) {
    t_reporting = true;
    write_stderr("trailnav: heap allocation on armed real-time thread '");
    write_stderr(slot->name);
    write_stderr("'\n");
    std::abort();
  }
}

}  // namespace detail
}  // namespace trailnav::alloc_guard
