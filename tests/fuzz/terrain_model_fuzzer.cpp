// Fuzzes the terrain model file (RandomForest::parse): any bytes give a
// forest or a message, never a crash or a walk out of the tables; a forest
// that loads predicts distributions and writes back the same bytes.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "check.hpp"

#include "trailnav/perception/random_forest.hpp"

using namespace trailnav;
using namespace trailnav::perception;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto loaded = RandomForest::parse(std::span<const std::uint8_t>(data, size), "fuzz.tnrf");
  check(loaded.forest.has_value() != !loaded.error.empty());
  if (!loaded.forest) return 0;
  const RandomForest& f = *loaded.forest;
  for (const FeatureVector& v : {FeatureVector{0, 0, 0, 0, 0, 0}, FeatureVector{255, 40, 10, 1e-3f, 45, 12},
                                 FeatureVector{-1e30f, 1e30f, NAN, INFINITY, -0.0f, 1e30f}}) {
    ClassDistribution p;
    f.predict(v, p);
    float sum = 0.0f;
    for (float x : p) {
      check(x >= 0.0f && x <= 1.0f + 1e-5f);
      sum += x;
    }
    check(std::abs(sum - 1.0f) < 1e-2f);
  }
  // Round trip: what loads, saves to the same bytes; a version 3 file (no
  // feature settings) as version 4 whose settings say nothing, the same
  // forest.
  const std::string path = "/tmp/trailnav-fuzz-model-" + std::to_string(::getpid()) + ".tnrf";
  check(f.save(path).is_ok());
  std::ifstream in(path, std::ios::binary);
  const std::vector<std::uint8_t> back((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::remove(path.c_str());
  if (data[8] == RandomForest::kVersion) {
    check(back.size() == size && std::equal(back.begin(), back.end(), data));
  } else {
    check(data[8] == 3 && !f.feature_settings().said());
    check(back.size() == size + RandomForest::kSettingsBytes);
    const std::size_t settings = 48;  // after the header and the lidar field
    check(std::equal(data + 12, data + settings, back.begin() + 12));
    check(std::all_of(back.begin() + settings, back.begin() + settings + RandomForest::kSettingsBytes,
                      [](std::uint8_t b) { return b == 0; }));
    check(std::equal(data + settings, data + size - 4, back.begin() + settings + RandomForest::kSettingsBytes));
  }
  return 0;
}
