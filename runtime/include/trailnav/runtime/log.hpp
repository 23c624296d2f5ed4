// Logging that real-time threads may use: a call formats into a fixed-size
// record on the caller's stack and pushes it through a bounded lock-free
// queue to the logger thread, which writes stderr or the systemd journal.
// Nothing on the caller's side allocates, locks or makes a system call; when
// the queue is full the record is dropped and counted.
//
// Before start() (start-up, command-line tools) records are written to
// stderr directly by the calling thread.
#pragma once

#include <cstddef>
#include <cstdint>

namespace trailnav::log {

enum class Level : std::uint8_t { debug = 0, info = 1, warn = 2, error = 3 };

enum class Sink : std::uint8_t {
  automatic,  // the journal when stderr is connected to it (JOURNAL_STREAM), else stderr
  stderr_only,
  journal,
};

inline constexpr std::size_t kMessageLength = 224;

void write(Level level, const char* format, ...) noexcept __attribute__((format(printf, 2, 3)));

void set_min_level(Level level) noexcept;
Level min_level() noexcept;

// Starts the logger thread (start-up only; allocates its thread).
void start(Sink sink = Sink::automatic);
// Drains the queue and stops the logger thread.
void stop();
bool running() noexcept;

// Records dropped because the queue was full.
std::uint64_t dropped() noexcept;
// Records written by the logger thread so far.
std::uint64_t written() noexcept;

const char* level_name(Level level) noexcept;
// Parses "debug", "info", "warn" or "error"; returns false for anything else.
bool parse_level(const char* text, Level& out) noexcept;

}  // namespace trailnav::log

#define TN_LOG_DEBUG(...) ::trailnav::log::write(::trailnav::log::Level::debug, __VA_ARGS__)
#define TN_LOG_INFO(...) ::trailnav::log::write(::trailnav::log::Level::info, __VA_ARGS__)
#define TN_LOG_WARN(...) ::trailnav::log::write(::trailnav::log::Level::warn, __VA_ARGS__)
#define TN_LOG_ERROR(...) ::trailnav::log::write(::trailnav::log::Level::error, __VA_ARGS__)
