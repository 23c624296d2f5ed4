#include "trailnav/perception/trav_model_file.hpp"

#include <zlib.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>

#include "trailnav/runtime/atomic_file.hpp"
#include "trailnav/runtime/le_bytes.hpp"

namespace trailnav::perception::trav {
namespace {

constexpr std::uint8_t kMagic[8] = {'T', 'N', 'T', 'R', 'A', 'V', 0x1a, '\n'};

using le::put_f32;
using le::put_f64;
using le::put_u32;
using le::put_u64;
using le::Reader;

}  // namespace

const TravModelSet* TravModelFile::set(FeatureSet s) const noexcept {
  for (const TravModelSet& t : sets) {
    if (t.vocabulary.set == s) return &t;
  }
  return nullptr;
}

namespace {

// One feature set: its vocabulary, learner settings and `count` models'
// counts (model(i) gives the i-th). Appends only: no allocation when `out`
// has the room (trav_model_bound()).
template <typename Model>
void put_set(std::vector<std::uint8_t>& out, const VocabularyConfig& vocabulary, const LearnerConfig& l,
             std::uint32_t count, const Model& model) noexcept {
  put_u32(out, static_cast<std::uint32_t>(vocabulary.set));
  for (const Binning& b : vocabulary.bins) {
    put_f32(out, b.width);
    put_u32(out, b.bins);
  }
  for (double d : {l.alpha_p, l.alpha_n, l.epsilon, l.chi2_alpha, l.min_expected, l.prior}) put_f64(out, d);
  put_u32(out, l.max_models);
  put_u32(out, count);
  for (std::uint32_t i = 0; i < count; ++i) {
    const WordCounts& k = model(i);
    put_u64(out, k.total_positive());
    put_u64(out, k.total_unlabelled());
    std::uint32_t entries = 0;
    for (std::uint32_t w = 0; w < k.vocabulary(); ++w) entries += (k.positive(w) != 0 || k.unlabelled(w) != 0) ? 1u : 0u;
    put_u32(out, entries);
    for (std::uint32_t w = 0; w < k.vocabulary(); ++w) {
      if (k.positive(w) == 0 && k.unlabelled(w) == 0) continue;
      put_u32(out, w);
      put_u32(out, k.positive(w));
      put_u32(out, k.unlabelled(w));
    }
  }
}

void put_header(std::vector<std::uint8_t>& out, std::string_view profile, std::uint32_t sets) noexcept {
  out.insert(out.end(), std::begin(kMagic), std::end(kMagic));
  put_u32(out, kModelFileVersion);
  put_u32(out, static_cast<std::uint32_t>(profile.size()));
  out.insert(out.end(), profile.begin(), profile.end());
  put_u32(out, sets);
}

void put_crc(std::vector<std::uint8_t>& out) noexcept {
  put_u32(out, static_cast<std::uint32_t>(crc32(0L, out.data(), static_cast<uInt>(out.size()))));
}

}  // namespace

std::vector<std::uint8_t> serialize_trav_model(const TravModelFile& m) {
  std::vector<std::uint8_t> out;
  put_header(out, m.profile, static_cast<std::uint32_t>(m.sets.size()));
  for (const TravModelSet& t : m.sets) {
    put_set(out, t.vocabulary, t.learner, static_cast<std::uint32_t>(t.models.size()),
            [&](std::uint32_t i) -> const WordCounts& { return t.models[i]; });
  }
  put_crc(out);
  return out;
}

std::size_t trav_model_bound(std::size_t profile, std::uint32_t vocabulary, std::uint32_t models) noexcept {
  const std::size_t header = sizeof kMagic + 4 + 4 + profile + 4;
  const std::size_t set = 4 + kDims * 8 + 6 * 8 + 4 + 4;
  const std::size_t model = 8 + 8 + 4 + static_cast<std::size_t>(vocabulary) * 12;
  return header + set + static_cast<std::size_t>(models) * model + 4;
}

void serialize_trav_models(std::string_view profile, const TravModels& models, std::vector<std::uint8_t>& out) noexcept {
  out.clear();
  put_header(out, profile, 1);
  put_set(out, models.vocabulary().config(), models.config(), models.models(),
          [&](std::uint32_t i) -> const WordCounts& { return models.counts(i); });
  put_crc(out);
}

Status save_trav_model(const std::string& path, const TravModelFile& model) {
  const std::vector<std::uint8_t> bytes = serialize_trav_model(model);
  if (const int e = AtomicFile(path).write(bytes); e != 0) {
    return Status::error("cannot write " + path + ": " + std::strerror(e));
  }
  return Status::ok();
}

LoadedTravModel load_trav_model(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {std::nullopt, path + ": cannot open: " + std::strerror(errno)};
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return parse_trav_model(bytes, path);
}

LoadedTravModel parse_trav_model(std::span<const std::uint8_t> data, const std::string& name) {
  auto fail = [&](const std::string& what) { return LoadedTravModel{std::nullopt, name + ": " + what}; };
  if (data.size() < sizeof kMagic || std::memcmp(data.data(), kMagic, sizeof kMagic) != 0) {
    return fail("not a trailnav traversability model (trailnav trav-train writes them)");
  }
  Reader r(data.subspan(sizeof kMagic));
  std::uint32_t version = 0;
  if (!r.u32(version)) return fail("truncated header");
  if (version == 1) {
    return fail("model format version 1: its words are the thesis' five feature dimensions, without the height "
                "above the ground this build adds (docs/traversability.md): train it again with trailnav trav-train");
  }
  if (version == 2) {
    return fail("model format version 2: its words have six feature dimensions, without the depth below the ground "
                "this build adds (docs/traversability.md): train it again with trailnav trav-train");
  }
  if (version != kModelFileVersion) {
    return fail("model format version " + std::to_string(version) + "; this build reads version " +
                std::to_string(kModelFileVersion));
  }
  if (data.size() < sizeof kMagic + 8) return fail("truncated");
  const auto crc = static_cast<std::uint32_t>(crc32(0L, data.data(), static_cast<uInt>(data.size() - 4)));
  std::uint32_t stored = 0;
  for (std::size_t i = 0; i < 4; ++i) stored |= static_cast<std::uint32_t>(data[data.size() - 4 + i]) << (8 * i);
  if (stored != crc) return fail("checksum mismatch: the file is truncated or corrupt");
  Reader body(data.subspan(sizeof kMagic + 4, data.size() - sizeof kMagic - 8));

  TravModelFile m;
  std::uint32_t profile_len = 0;
  if (!body.u32(profile_len)) return fail("truncated header");
  if (profile_len > kMaxProfileName) return fail("robot profile name longer than " + std::to_string(kMaxProfileName) + " characters");
  if (!body.bytes(profile_len, m.profile)) return fail("truncated header");
  for (char c : m.profile) {
    if (c < 0x20 || c > 0x7e) return fail("robot profile name is not printable ASCII");
  }
  std::uint32_t sets = 0;
  if (!body.u32(sets)) return fail("truncated header");
  if (sets < 1 || sets > static_cast<std::uint32_t>(kFeatureSets)) {
    return fail(std::to_string(sets) + " feature sets; a model holds 1 to " + std::to_string(kFeatureSets));
  }
  for (std::uint32_t si = 0; si < sets; ++si) {
    TravModelSet t;
    std::uint32_t set = 0;
    if (!body.u32(set)) return fail("truncated header");
    if (set >= static_cast<std::uint32_t>(kFeatureSets)) return fail("unknown feature set " + std::to_string(set));
    t.vocabulary.set = static_cast<FeatureSet>(set);
    if (m.set(t.vocabulary.set) != nullptr) {
      return fail("feature set " + std::string(feature_set_name(t.vocabulary.set)) + " twice");
    }
    const std::string in = "feature set " + std::string(feature_set_name(t.vocabulary.set)) + ": ";
    for (Binning& b : t.vocabulary.bins) {
      if (!body.f32(b.width) || !body.u32(b.bins)) return fail(in + "truncated");
    }
    if (std::string why = check_vocabulary(t.vocabulary); !why.empty()) return fail(in + "vocabulary: " + why);
    LearnerConfig& l = t.learner;
    for (double* d : {&l.alpha_p, &l.alpha_n, &l.epsilon, &l.chi2_alpha, &l.min_expected, &l.prior}) {
      if (!body.f64(*d)) return fail(in + "truncated");
    }
    if (!body.u32(l.max_models)) return fail(in + "truncated");
    if (std::string why = check_learner(l); !why.empty()) return fail(in + "learner settings: " + why);
    const std::uint32_t size = Vocabulary(t.vocabulary).size();
    std::uint32_t models = 0;
    if (!body.u32(models)) return fail(in + "truncated");
    if (models > l.max_models) {
      return fail(in + std::to_string(models) + " terrain models, more than its max_models " + std::to_string(l.max_models));
    }
    for (std::uint32_t i = 0; i < models; ++i) {
      const std::string which = in + "terrain model " + std::to_string(i) + ": ";
      std::uint64_t np = 0, nu = 0;
      std::uint32_t entries = 0;
      if (!body.u64(np) || !body.u64(nu) || !body.u32(entries)) return fail(which + "truncated");
      if (entries > size) return fail(which + std::to_string(entries) + " words, the vocabulary has " + std::to_string(size));
      if (body.left() < 12ull * entries) return fail(which + "truncated");
      WordCounts k(size);
      std::int64_t last = -1;
      for (std::uint32_t e = 0; e < entries; ++e) {
        std::uint32_t w = 0, p = 0, u = 0;
        body.u32(w);
        body.u32(p);
        body.u32(u);
        if (w >= size) return fail(which + "word " + std::to_string(w) + " outside the vocabulary of " + std::to_string(size));
        if (static_cast<std::int64_t>(w) <= last) return fail(which + "words out of order");
        if (p == 0 && u == 0) return fail(which + "a stored word without a count");
        last = w;
        k.add(w, true, p);
        k.add(w, false, u);
      }
      if (k.total_positive() != np || k.total_unlabelled() != nu) {
        return fail(which + "the counts do not add up to the stored totals");
      }
      t.models.push_back(std::move(k));
    }
    m.sets.push_back(std::move(t));
  }
  if (body.left() != 0) return fail(std::to_string(body.left()) + " bytes after the last model");
  return {std::move(m), ""};
}

}  // namespace trailnav::perception::trav
