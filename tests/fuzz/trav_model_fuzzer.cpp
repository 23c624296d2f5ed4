// Fuzzes the traversability model file (parse_trav_model): any bytes give a
// model or a message, never a crash; a model that loads writes back the same
// bytes, and the learner built from it gives probabilities in [0, 1].
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "check.hpp"

#include "trailnav/perception/trav_model_file.hpp"

using namespace trailnav::perception::trav;

namespace {

void parse_one(std::span<const std::uint8_t> bytes) {
  const LoadedTravModel loaded = parse_trav_model(bytes, "fuzz.tntrav");
  check(loaded.model.has_value() != !loaded.error.empty());
  if (!loaded.model) return;
  const TravModelFile& m = *loaded.model;
  const std::vector<std::uint8_t> back = serialize_trav_model(m);
  check(back.size() == bytes.size() && std::equal(back.begin(), back.end(), bytes.begin()));
  for (const TravModelSet& t : m.sets) {
    // Keep the learner's tables small enough for the fuzzer's memory limit.
    const Vocabulary vocabulary(t.vocabulary);
    if (static_cast<std::uint64_t>(vocabulary.size()) * t.learner.max_models > (1u << 20)) continue;
    TravModels models(vocabulary, t.learner);
    models.set_models(t.models);
    const std::vector<std::uint32_t> words{0, vocabulary.size() - 1, vocabulary.size() / 2};
    for (Method method : {Method::pnb, Method::pos}) {
      const double p = models.probability(method, words);
      check(p >= 0.0 && p <= 1.0);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  parse_one(std::span<const std::uint8_t>(data, size));
  // The same bytes with their checksum made right, so that the fuzzer gets
  // past it to the structure behind.
  if (size >= 12) {
    std::vector<std::uint8_t> fixed(data, data + size);
    const auto crc = static_cast<std::uint32_t>(crc32(0L, fixed.data(), static_cast<uInt>(size - 4)));
    for (std::size_t i = 0; i < 4; ++i) fixed[size - 4 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    parse_one(fixed);
  }
  return 0;
}
