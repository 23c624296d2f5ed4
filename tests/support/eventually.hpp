// Waiting for threads without betting on the machine's speed: poll a
// condition until it holds or a deadline far beyond any plausible delay
// passes. A test then asserts the condition itself (and what the threads
// counted), never that it held after a fixed sleep; on an idle machine the
// wait ends at once, on a loaded one it takes what it takes.
#pragma once

#include <chrono>
#include <thread>

namespace trailnav::test {

// Polls `done()` every `step` until it returns true (then true) or `timeout`
// has passed (then false, after one last look).
template <class Done>
bool eventually(Done&& done, std::chrono::milliseconds timeout = std::chrono::seconds(30),
                std::chrono::milliseconds step = std::chrono::milliseconds(5)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(step);
  }
  return done();
}

}  // namespace trailnav::test
