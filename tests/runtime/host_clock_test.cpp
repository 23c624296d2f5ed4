// The host clock: CLOCK_REALTIME minus the steps of the system clock since
// start (runtime/host_clock.hpp). The arithmetic on given readings; the
// process's clock on this machine, whose clock is not stepped during the test
// (the kernel tests step a virtual machine's: tests/kernel).
#include <gtest/gtest.h>

#include <ctime>

#include "trailnav/runtime/host_clock.hpp"

using trailnav::HostClockRelation;
using trailnav::Nanos;

namespace {

constexpr Nanos kSec = 1'000'000'000;
constexpr Nanos kMs = 1'000'000;

Nanos realtime() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<Nanos>(ts.tv_sec) * kSec + ts.tv_nsec;
}

}  // namespace

// A robot PC that booted with its clock wrong by 3 hours, set right by chrony
// 40 s into the run, later set back 5 s by hand: host time carries on
// without a jump; stamps going out are on the system clock of the moment.
TEST(HostClockRelation, StepsAreTakenOutAndPutBackOnTheWayOut) {
  const Nanos boot_wrong = 1'700'000'000LL * kSec;  // what REALTIME said at start
  const Nanos mono0 = 1000 * kSec;
  HostClockRelation r(boot_wrong, mono0);
  EXPECT_EQ(r.update(boot_wrong + 10 * kSec, mono0 + 10 * kSec), 0);
  // NTP slews both clocks alike, and reading them one after the other leaves
  // them up to a few microseconds apart: no step.
  EXPECT_EQ(r.update(boot_wrong + 20 * kSec + 40'000, mono0 + 20 * kSec), 0);
  EXPECT_EQ(r.steps(), 0u);
  // chrony's makestep: +3 h.
  const Nanos three_hours = 3 * 3600 * kSec;
  EXPECT_EQ(r.update(boot_wrong + 40 * kSec + three_hours, mono0 + 40 * kSec), three_hours);
  EXPECT_EQ(r.steps(), 1u);
  // A CAN frame stamped by the kernel 1 s later, on the set clock: host time
  // 41 s after the start, as if nothing had been set.
  EXPECT_EQ(r.from_realtime(boot_wrong + 41 * kSec + three_hours), boot_wrong + 41 * kSec);
  // Its stamp going out: the system clock's.
  EXPECT_EQ(r.to_realtime(boot_wrong + 41 * kSec), boot_wrong + 41 * kSec + three_hours);
  // Back by 5 s.
  EXPECT_EQ(r.update(boot_wrong + 60 * kSec + three_hours - 5 * kSec, mono0 + 60 * kSec), three_hours - 5 * kSec);
  EXPECT_EQ(r.steps(), 2u);
  EXPECT_EQ(r.from_realtime(boot_wrong + 61 * kSec + three_hours - 5 * kSec), boot_wrong + 61 * kSec);
  // Within the tolerance of the current step: the same step.
  EXPECT_EQ(r.update(boot_wrong + 70 * kSec + three_hours - 5 * kSec + kMs / 2, mono0 + 70 * kSec), three_hours - 5 * kSec);
  EXPECT_EQ(r.steps(), 2u);
}

// On this machine, where nobody sets the clock during the test, host time is
// CLOCK_REALTIME, and conversions both ways are the identity.
TEST(HostClock, WithoutAStepHostTimeIsTheSystemClock) {
  trailnav::host_clock_start();
  for (int i = 0; i < 1000; ++i) {
    const Nanos before = realtime();
    const Nanos host = trailnav::host_now_ns();
    const Nanos after = realtime();
    ASSERT_GE(host, before);
    ASSERT_LE(host, after);
  }
  EXPECT_EQ(trailnav::host_clock_step_ns(), 0);
  EXPECT_EQ(trailnav::host_clock_steps(), 0u);
  const Nanos t = realtime();
  EXPECT_EQ(trailnav::host_from_realtime(t), t);
  EXPECT_EQ(trailnav::host_to_realtime(t), t);
}
