// The soak's five-minute version (label `slow`, outside CI; the full hour is
// toolchain/soak.sh): `trailnav demo --soak-minutes 5` must meet the soak's
// goals: RSS and file descriptors constant after the first minute, no
// real-time allocation, no overrun, map latency p99 at most 5 ms.
// Run it with: ctest --test-dir build/release -L slow -R Soak
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

TEST(Soak, FiveMinutesOfTheMixedRouteLooped) {
  const std::string out = "build/soak-5min";
  const std::string command = std::string(TRAILNAV_BINARY) +
                              " demo --scenario mixed-route --seconds 120 --out " + out +
                              " --png-every 0 --domain 78 --soak-minutes 5 --sample-every 10 2>&1";
  FILE* p = ::popen(command.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string text;
  char buffer[4096];
  for (std::size_t n; (n = std::fread(buffer, 1, sizeof buffer, p)) > 0;) text.append(buffer, n);
  const int status = ::pclose(p);
  std::printf("%s", text.c_str());
  EXPECT_EQ(status, 0) << "the soak's goals were not met";
  EXPECT_NE(text.find("soak goals met"), std::string::npos);
  // 30 samples, one every 10 s.
  std::ifstream csv(out + "/soak.csv");
  std::string line;
  int rows = -1;
  while (std::getline(csv, line)) ++rows;
  EXPECT_GE(rows, 29);
}
