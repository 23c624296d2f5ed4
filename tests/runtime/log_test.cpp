#include "trailnav/runtime/log.hpp"

#include <gtest/gtest.h>

namespace trailnav {
namespace {

TEST(Log, EveryRecordIsWrittenOrCountedAsDropped) {
  log::set_min_level(log::Level::info);
  log::start(log::Sink::stderr_only);
  const std::uint64_t written_before = log::written();
  const std::uint64_t dropped_before = log::dropped();
  constexpr int kRecords = 3000;  // more than the queue holds: some may be dropped
  for (int i = 0; i < kRecords; ++i) TN_LOG_INFO("log test record %d of %d", i, kRecords);
  log::stop();
  const std::uint64_t accounted = (log::written() - written_before) + (log::dropped() - dropped_before);
  EXPECT_EQ(accounted, static_cast<std::uint64_t>(kRecords));
  EXPECT_FALSE(log::running());
}

TEST(Log, RecordsBelowTheMinimumLevelAreNeitherWrittenNorDropped) {
  log::set_min_level(log::Level::warn);
  log::start(log::Sink::stderr_only);
  const std::uint64_t written_before = log::written();
  const std::uint64_t dropped_before = log::dropped();
  TN_LOG_INFO("filtered out");
  TN_LOG_DEBUG("filtered out");
  TN_LOG_WARN("kept");
  log::stop();
  EXPECT_EQ(log::written() - written_before, 1u);
  EXPECT_EQ(log::dropped(), dropped_before);
  log::set_min_level(log::Level::info);
}

TEST(Log, LevelNamesRoundTrip) {
  for (log::Level level : {log::Level::debug, log::Level::info, log::Level::warn, log::Level::error}) {
    log::Level parsed = log::Level::error;
    ASSERT_TRUE(log::parse_level(log::level_name(level), parsed));
    EXPECT_EQ(parsed, level);
  }
  log::Level unused = log::Level::info;
  EXPECT_FALSE(log::parse_level("verbose", unused));
}

}  // namespace
}  // namespace trailnav
