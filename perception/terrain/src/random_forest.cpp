#include "trailnav/perception/random_forest.hpp"

#include "trailnav/runtime/atomic_file.hpp"
#include "trailnav/runtime/le_bytes.hpp"

#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>

namespace trailnav::perception {

namespace {

constexpr char kMagic[8] = {'T', 'N', 'T', 'E', 'R', 'R', 'F', '\0'};
constexpr std::uint32_t kMaxNodes = 1u << 24;
constexpr std::uint32_t kMaxTrees = 4096;

using le::put_f32;
using le::put_u32;

std::string describe_node(std::size_t tree, std::size_t node) {
  return "tree " + std::to_string(tree) + ", node " + std::to_string(node);
}

}  // namespace

RandomForest::Loaded RandomForest::from_parts(std::vector<std::uint32_t> roots, std::vector<ForestNode> nodes,
                                              std::vector<float> leaves) {
  Loaded result;
  if (roots.empty()) return {std::nullopt, "the forest has no trees"};
  if (roots.size() > kMaxTrees) return {std::nullopt, "too many trees (" + std::to_string(roots.size()) + ")"};
  if (nodes.size() > kMaxNodes) return {std::nullopt, "too many nodes (" + std::to_string(nodes.size()) + ")"};
  if (leaves.size() % kTerrainClasses != 0) return {std::nullopt, "the leaf table is not a whole number of rows"};
  const std::size_t leaf_rows = leaves.size() / kTerrainClasses;
  for (std::size_t r = 0; r < leaf_rows; ++r) {
    float sum = 0.0f;
    for (int t = 0; t < kTerrainClasses; ++t) {
      const float p = leaves[r * kTerrainClasses + static_cast<std::size_t>(t)];
      if (!std::isfinite(p) || p < 0.0f || p > 1.0f) {
        return {std::nullopt, "leaf " + std::to_string(r) + ": probability outside [0, 1]"};
      }
      sum += p;
    }
    if (std::abs(sum - 1.0f) > 1e-3f) return {std::nullopt, "leaf " + std::to_string(r) + ": probabilities do not sum to 1"};
  }
  // Trees are consecutive runs of nodes in pre-order; check every tree walks
  // only forward and inside its own run, so inference always ends at a leaf.
  std::size_t max_depth = 0;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack;  // node, depth
  for (std::size_t t = 0; t < roots.size(); ++t) {
    const std::uint32_t begin = roots[t];
    const std::uint32_t end = t + 1 < roots.size() ? roots[t + 1] : static_cast<std::uint32_t>(nodes.size());
    if (begin >= end || end > nodes.size()) {
      return {std::nullopt, "tree " + std::to_string(t) + ": its first node is out of order or out of range"};
    }
    if (t == 0 && begin != 0) return {std::nullopt, "tree 0 does not start at node 0"};
    std::size_t visited = 0;
    stack.assign(1, {begin, 1});
    while (!stack.empty()) {
      const auto [i, depth] = stack.back();
      stack.pop_back();
      ++visited;
      if (visited > end - begin) return {std::nullopt, describe_node(t, i) + ": nodes are shared or form a cycle"};
      max_depth = std::max<std::size_t>(max_depth, depth);
      const ForestNode& n = nodes[i];
      if (n.feature < 0) {
        if (n.next < 0 || static_cast<std::size_t>(n.next) >= leaf_rows) {
          return {std::nullopt, describe_node(t, i) + ": leaf row " + std::to_string(n.next) + " out of range"};
        }
        continue;
      }
      if (n.feature >= kTerrainFeatures) {
        return {std::nullopt, describe_node(t, i) + ": feature " + std::to_string(n.feature) + " out of range"};
      }
      if (!std::isfinite(n.threshold)) return {std::nullopt, describe_node(t, i) + ": threshold is not a number"};
      if (i + 1 >= end || n.next <= static_cast<std::int32_t>(i + 1) || static_cast<std::uint32_t>(n.next) >= end) {
        return {std::nullopt, describe_node(t, i) + ": child index out of range"};
      }
      stack.push_back({static_cast<std::uint32_t>(n.next), depth + 1});
      stack.push_back({i + 1, depth + 1});
    }
    if (visited != end - begin) return {std::nullopt, "tree " + std::to_string(t) + ": has nodes no path reaches"};
  }
  RandomForest f;
  static_assert(kTerrainFeatures < static_cast<int>(kLeafCode) && kMaxNodes <= (1u << 29));
  f.walk_.resize(nodes.size());
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const ForestNode& n = nodes[i];
    const auto code = n.feature < 0 ? kLeafCode : static_cast<std::uint32_t>(n.feature);
    f.walk_[i] = {n.threshold, (static_cast<std::uint32_t>(n.next) << 3) | code};  // a leaf keeps its (unread) threshold so save() writes the same bytes
  }
  f.roots_ = std::move(roots);
  f.leaves_ = std::move(leaves);
  f.max_depth_ = max_depth;
  result.forest = std::move(f);
  return result;
}

std::vector<ForestNode> RandomForest::node_table() const {
  std::vector<ForestNode> table(walk_.size());
  for (std::size_t i = 0; i < walk_.size(); ++i) {
    const std::uint32_t code = walk_[i].word & kLeafCode;
    ForestNode& n = table[i];
    n.feature = code == kLeafCode ? std::int16_t{-1} : static_cast<std::int16_t>(code);
    n.threshold = walk_[i].threshold;
    n.next = static_cast<std::int32_t>(walk_[i].word >> 3);
  }
  return table;
}

Status RandomForest::save(const std::string& path) const {
  std::vector<std::uint8_t> out(std::begin(kMagic), std::end(kMagic));
  put_u32(out, kVersion);
  put_u32(out, kTerrainFeatures);
  put_u32(out, kTerrainClasses);
  put_u32(out, static_cast<std::uint32_t>(roots_.size()));
  put_u32(out, static_cast<std::uint32_t>(walk_.size()));
  put_u32(out, static_cast<std::uint32_t>(leaves()));
  for (std::size_t i = 0; i < kLidarBytes; ++i) out.push_back(i < lidar_.size() ? static_cast<std::uint8_t>(lidar_[i]) : 0);
  put_f32(out, settings_.resolution);
  put_u32(out, settings_.min_points);
  put_f32(out, settings_.min_range);
  put_f32(out, settings_.max_range);
  for (std::uint32_t r : roots_) put_u32(out, r);
  for (const ForestNode& n : node_table()) {
    put_u32(out, static_cast<std::uint16_t>(n.feature));
    put_f32(out, n.threshold);
    put_u32(out, static_cast<std::uint32_t>(n.next));
  }
  for (float p : leaves_) put_f32(out, p);
  put_u32(out, static_cast<std::uint32_t>(crc32(0L, out.data(), static_cast<uInt>(out.size()))));
  // Whole or not at all, and flushed to the disk (runtime/atomic_file.hpp).
  if (const int e = AtomicFile(path).write(out); e != 0) {
    return Status::error("cannot write " + path + ": " + std::strerror(e));
  }
  return Status::ok();
}

RandomForest::Loaded RandomForest::load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {std::nullopt, path + ": cannot open: " + std::strerror(errno)};
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return parse(bytes, path);
}

RandomForest::Loaded RandomForest::parse(std::span<const std::uint8_t> data, const std::string& path) {
  auto fail = [&](const std::string& what) { return Loaded{std::nullopt, path + ": " + what}; };
  if (data.size() < sizeof kMagic || std::memcmp(data.data(), kMagic, sizeof kMagic) != 0) {
    return fail("not a trailnav terrain model (trailnav terrain-train writes them)");
  }
  le::Reader c(data);
  std::uint32_t skip;
  c.u32(skip);
  c.u32(skip);  // the magic
  std::uint32_t version = 0, features = 0, classes = 0, trees = 0, nodes = 0, leaves = 0;
  if (!c.u32(version)) return fail("truncated header");
  if (version == 1 || version == 2) {
    return fail("model format version " + std::to_string(version) +
                ": a forest of the five per-cell features; this build's forests (version " + std::to_string(kVersion) +
                ") also use the remission spread around the cell, so train the model again with trailnav "
                "terrain-train (toolchain/train-terrain-model.sh rebuilds the shipped ones)");
  }
  if (version != kVersion && version != 3) {
    return fail("model format version " + std::to_string(version) + "; this build reads version " +
                std::to_string(kVersion));
  }
  if (!c.u32(features) || !c.u32(classes) || !c.u32(trees) || !c.u32(nodes) || !c.u32(leaves)) return fail("truncated header");
  if (features != kTerrainFeatures || classes != kTerrainClasses) {
    return fail("model of " + std::to_string(features) + " features and " + std::to_string(classes) +
                " classes; this build uses " + std::to_string(kTerrainFeatures) + " and " + std::to_string(kTerrainClasses));
  }
  if (trees == 0 || trees > kMaxTrees || nodes > kMaxNodes || leaves > kMaxNodes) return fail("implausible sizes in the header");
  const std::size_t settings_bytes = version >= 4 ? kSettingsBytes : 0;
  const std::size_t expected =
      c.pos() + kLidarBytes + settings_bytes + 4ull * trees + 12ull * nodes + 4ull * kTerrainClasses * leaves + 4;
  if (data.size() != expected) {
    return fail("size " + std::to_string(data.size()) + " bytes, the header announces " + std::to_string(expected) +
                " (truncated or corrupt)");
  }
  const auto crc = static_cast<std::uint32_t>(crc32(0L, data.data(), static_cast<uInt>(data.size() - 4)));
  std::uint32_t stored = 0;
  for (std::size_t i = 0; i < 4; ++i) stored |= static_cast<std::uint32_t>(data[data.size() - 4 + i]) << (8 * i);
  if (stored != crc) return fail("checksum mismatch: the file is corrupt");
  const std::uint8_t* lidar_field = data.data() + c.pos();
  std::size_t lidar_chars = 0;
  while (lidar_chars < kLidarBytes && lidar_field[lidar_chars] != 0) ++lidar_chars;
  for (std::size_t i = lidar_chars; i < kLidarBytes; ++i) {
    if (lidar_field[i] != 0) return fail("malformed lidar field (text after its end)");
  }
  const std::string lidar(reinterpret_cast<const char*>(lidar_field), lidar_chars);
  std::uint32_t skip_lidar;
  for (std::size_t i = 0; i < kLidarBytes / 4; ++i) c.u32(skip_lidar);
  FeatureSettings settings;
  if (version >= 4) {
    c.f32(settings.resolution);
    c.u32(settings.min_points);
    c.f32(settings.min_range);
    c.f32(settings.max_range);
  }
  std::vector<std::uint32_t> roots(trees);
  for (auto& r : roots) c.u32(r);
  std::vector<ForestNode> table(nodes);
  for (ForestNode& n : table) {
    std::uint32_t feature = 0, next = 0;
    c.u32(feature);
    c.f32(n.threshold);
    c.u32(next);
    n.feature = static_cast<std::int16_t>(static_cast<std::uint16_t>(feature & 0xFFFF));
    if ((feature >> 16) != 0) return fail("node with a malformed feature field");
    n.next = static_cast<std::int32_t>(next);
  }
  std::vector<float> leaf_table(static_cast<std::size_t>(leaves) * kTerrainClasses);
  for (float& p : leaf_table) c.f32(p);
  Loaded loaded = from_parts(std::move(roots), std::move(table), std::move(leaf_table));
  if (!loaded.forest) {
    loaded.error = path + ": " + loaded.error;
    return loaded;
  }
  if (std::string e = loaded.forest->set_lidar(lidar); !e.empty()) return fail("lidar field: " + e);
  if (std::string e = loaded.forest->set_feature_settings(settings); !e.empty()) return fail("feature settings: " + e);
  return loaded;
}

std::string RandomForest::set_lidar(std::string_view name) {
  if (name.size() >= kLidarBytes) return "a lidar name has at most " + std::to_string(kLidarBytes - 1) + " characters";
  for (char ch : name) {
    if (ch < 0x21 || ch > 0x7E) return "a lidar name is printable ASCII without spaces";
  }
  lidar_.assign(name);
  return {};
}

std::string RandomForest::set_feature_settings(const FeatureSettings& s) {
  if (s == FeatureSettings{}) {
    settings_ = s;
    return {};
  }
  // The ranges TerrainConfig accepts (terrain_config.cpp).
  if (!(s.resolution >= 0.02f && s.resolution <= 2.0f)) return "map resolution " + std::to_string(s.resolution) + " m (0.02 to 2)";
  if (s.min_points < 3 || s.min_points > 100000) return "min_points " + std::to_string(s.min_points) + " (3 to 100000)";
  if (!(s.min_range >= 0.0f && s.min_range <= 50.0f)) return "min_range " + std::to_string(s.min_range) + " m (0 to 50)";
  if (!(s.max_range >= 1.0f && s.max_range <= 300.0f && s.max_range > s.min_range)) {
    return "max_range " + std::to_string(s.max_range) + " m (1 to 300, above min_range)";
  }
  settings_ = s;
  return {};
}

std::string check_forest_lidar(const RandomForest& forest, std::string_view lidar, const std::string& model_path) {
  const std::string& trained = forest.lidar();
  if (trained.empty() || lidar.empty()) return {};
  const auto lower = [](std::string_view s) {
    std::string out(s);
    for (char& ch : out) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return out;
  };
  if (lower(trained) == lower(lidar)) return {};
  return model_path + ": the terrain model was trained on " + trained + " returns, this lidar is " + std::string(lidar) +
         ": its remissions differ (another scale, other per-laser limits), so the classes would be wrong. Train a "
         "model for this lidar (trailnav terrain-train, docs/terrain.md)";
}

}  // namespace trailnav::perception
