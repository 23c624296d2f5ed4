#include "trailnav/runtime/log.hpp"

#include <pthread.h>
#include <syslog.h>
#include <systemd/sd-journal.h>
#include <unistd.h>

#include <atomic>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <thread>

#include "trailnav/runtime/mpsc_queue.hpp"

namespace trailnav::log {
namespace {

struct Record {
  std::int64_t wall_time_ns = 0;
  Level level = Level::info;
  char thread[16] = {};
  char text[kMessageLength] = {};
};

constexpr std::size_t kQueueCapacity = 1024;

MpscQueue<Record, kQueueCapacity> g_queue;  // static storage, never allocated
std::atomic<Level> g_min_level{Level::info};
std::atomic<bool> g_running{false};
std::atomic<bool> g_stop_requested{false};
std::atomic<std::uint64_t> g_dropped{0};
std::atomic<std::uint64_t> g_written{0};
std::atomic<Sink> g_sink{Sink::stderr_only};
std::thread g_thread;

// The calling thread's name, read from the kernel once per thread (a
// system call) and kept; a thread renamed after its first log line keeps
// the old name in its records.
__attribute__((tls_model("initial-exec"))) thread_local char t_name[16] = {};
__attribute__((tls_model("initial-exec"))) thread_local bool t_name_known = false;

void copy_thread_name(char (&out)[16]) noexcept {
  if (!t_name_known) {
    pthread_getname_np(pthread_self(), t_name, sizeof t_name);
    t_name_known = true;
  }
  std::memcpy(out, t_name, sizeof t_name);
}

std::int64_t wall_time_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

int syslog_priority(Level level) noexcept {
  switch (level) {
    case Level::debug: return LOG_DEBUG;
    case Level::info: return LOG_INFO;
    case Level::warn: return LOG_WARNING;
    case Level::error: return LOG_ERR;
  }
  return LOG_INFO;
}

void emit(const Record& record, Sink sink) noexcept {
  if (sink == Sink::journal) {
    sd_journal_send("MESSAGE=%s", record.text, "PRIORITY=%d", syslog_priority(record.level),
                    "TRAILNAV_THREAD=%s", record.thread, nullptr);
    return;
  }
  const auto seconds = static_cast<time_t>(record.wall_time_ns / 1'000'000'000);
  const auto millis = static_cast<int>((record.wall_time_ns / 1'000'000) % 1000);
  tm utc{};
  gmtime_r(&seconds, &utc);
  char line[kMessageLength + 96];
  const int n = std::snprintf(line, sizeof line, "%02d:%02d:%02d.%03d %-5s [%s] %s\n", utc.tm_hour,
                              utc.tm_min, utc.tm_sec, millis, level_name(record.level), record.thread,
                              record.text);
  if (n > 0) {
    const auto length = static_cast<std::size_t>(n) < sizeof line ? static_cast<std::size_t>(n) : sizeof line - 1;
    [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, line, length);
  }
}

void drain() noexcept {
  Record record;
  const Sink sink = g_sink.load(std::memory_order_acquire);
  while (g_queue.try_pop(record)) {
    emit(record, sink);
    g_written.fetch_add(1, std::memory_order_relaxed);
  }
}

void logger_main() noexcept {
  pthread_setname_np(pthread_self(), "tn-logger");
  const timespec period{0, 20'000'000};
  while (!g_stop_requested.load(std::memory_order_acquire)) {
    drain();
    nanosleep(&period, nullptr);
  }
  drain();
}

}  // namespace

void write(Level level, const char* format, ...) noexcept {
  if (level < g_min_level.load(std::memory_order_relaxed)) return;
  Record record;
  record.wall_time_ns = wall_time_ns();
  record.level = level;
  copy_thread_name(record.thread);
  va_list args;
  va_start(args, format);
  std::vsnprintf(record.text, sizeof record.text, format, args);
  va_end(args);

  if (!g_running.load(std::memory_order_acquire)) {
    emit(record, Sink::stderr_only);
    return;
  }
  if (!g_queue.try_push(record)) g_dropped.fetch_add(1, std::memory_order_relaxed);
}

void set_min_level(Level level) noexcept { g_min_level.store(level, std::memory_order_relaxed); }
Level min_level() noexcept { return g_min_level.load(std::memory_order_relaxed); }

void start(Sink sink) {
  if (g_running.load(std::memory_order_acquire)) return;
  if (sink == Sink::automatic) {
    sink = std::getenv("JOURNAL_STREAM") != nullptr ? Sink::journal : Sink::stderr_only;
  }
  g_sink.store(sink, std::memory_order_release);
  g_stop_requested.store(false, std::memory_order_release);
  g_thread = std::thread(logger_main);
  g_running.store(true, std::memory_order_release);
}

void stop() {
  if (!g_running.load(std::memory_order_acquire)) return;
  g_stop_requested.store(true, std::memory_order_release);
  g_thread.join();
  g_running.store(false, std::memory_order_release);
  drain();  // anything pushed between the last drain and the flag
}

bool running() noexcept { return g_running.load(std::memory_order_acquire); }
std::uint64_t dropped() noexcept { return g_dropped.load(std::memory_order_relaxed); }
std::uint64_t written() noexcept { return g_written.load(std::memory_order_relaxed); }

const char* level_name(Level level) noexcept {
  switch (level) {
    case Level::debug: return "debug";
    case Level::info: return "info";
    case Level::warn: return "warn";
    case Level::error: return "error";
  }
  return "?";
}

bool parse_level(const char* text, Level& out) noexcept {
  for (Level level : {Level::debug, Level::info, Level::warn, Level::error}) {
    if (std::strcmp(text, level_name(level)) == 0) {
      out = level;
      return true;
    }
  }
  return false;
}

}  // namespace trailnav::log
