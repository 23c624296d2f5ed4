#include "trailnav/perception/forest_training.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numeric>
#include <thread>

namespace trailnav::perception {

namespace {

// splitmix64: small, fast and the same on every platform (the standard
// library's distributions are not).
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(seed) {}
  std::uint64_t next() noexcept {
    std::uint64_t z = (s_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, n) for n < 2^32 (multiply-shift; the bias is below n / 2^32).
  std::uint64_t below(std::uint64_t n) noexcept { return ((next() >> 32) * n) >> 32; }

 private:
  std::uint64_t s_;
};

struct Tree {
  std::vector<ForestNode> nodes;  // indices local to the tree
  std::vector<float> leaves;
  std::vector<std::uint8_t> in_bag;  // per sample: drawn at least once
};

class TreeBuilder {
 public:
  TreeBuilder(const LabelledFeatures& data, const ForestParams& p, std::uint64_t seed) : data_(data), p_(p), rng_(seed) {}

  Tree build() {
    Tree tree;
    const std::size_t n = data_.size();
    idx_.resize(n);
    tree.in_bag.assign(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      idx_[i] = static_cast<std::uint32_t>(rng_.below(n));
      tree.in_bag[idx_[i]] = 1;
    }
    scratch_.reserve(n);
    struct Job {
      std::uint32_t begin, end, depth;
      std::int64_t patch;  // node whose right child this is (-1: a left child or the root)
    };
    std::vector<Job> stack{{0, static_cast<std::uint32_t>(n), 1, -1}};
    while (!stack.empty()) {
      const Job job = stack.back();
      stack.pop_back();
      const auto self = static_cast<std::int32_t>(tree.nodes.size());
      if (job.patch >= 0) tree.nodes[static_cast<std::size_t>(job.patch)].next = self;
      Split split;
      const bool can_split = static_cast<int>(job.end - job.begin) >= p_.min_samples_split &&
                             (p_.max_depth == 0 || static_cast<int>(job.depth) < p_.max_depth) &&
                             find_split(job.begin, job.end, split);
      if (!can_split) {
        ForestNode leaf;
        leaf.feature = -1;
        leaf.next = static_cast<std::int32_t>(tree.leaves.size() / kTerrainClasses);
        const auto counts = count(job.begin, job.end);
        const auto total = static_cast<float>(job.end - job.begin);
        for (int t = 0; t < kTerrainClasses; ++t) tree.leaves.push_back(static_cast<float>(counts[static_cast<std::size_t>(t)]) / total);
        tree.nodes.push_back(leaf);
        continue;
      }
      const std::uint32_t mid = partition(job.begin, job.end, split);
      ForestNode inner;
      inner.feature = static_cast<std::int16_t>(split.feature);
      inner.threshold = split.threshold;
      tree.nodes.push_back(inner);
      stack.push_back({mid, job.end, job.depth + 1, self});    // right: popped after the left subtree
      stack.push_back({job.begin, mid, job.depth + 1, -1});    // left: the next node
    }
    return tree;
  }

 private:
  struct Split {
    int feature = -1;
    float threshold = 0.0f;
    double score = 0.0;
  };

  std::array<std::uint64_t, kTerrainClasses> count(std::uint32_t begin, std::uint32_t end) const {
    std::array<std::uint64_t, kTerrainClasses> c{};
    for (std::uint32_t i = begin; i < end; ++i) ++c[data_.labels[idx_[i]]];
    return c;
  }

  // The best Gini split over `features_per_split` random features (more if
  // those are constant here); false when no feature separates the samples
  // or the node is pure.
  bool find_split(std::uint32_t begin, std::uint32_t end, Split& best) {
    const auto counts = count(begin, end);
    const double n = end - begin;
    double parent = 0.0;
    int classes_present = 0;
    for (auto c : counts) {
      parent += static_cast<double>(c) * static_cast<double>(c);
      classes_present += c > 0 ? 1 : 0;
    }
    if (classes_present <= 1) return false;
    parent /= n;
    std::array<int, kTerrainFeatures> order;
    std::iota(order.begin(), order.end(), 0);
    for (int i = 0; i < kTerrainFeatures - 1; ++i) {
      const auto j = i + static_cast<int>(rng_.below(static_cast<std::uint64_t>(kTerrainFeatures - i)));
      std::swap(order[static_cast<std::size_t>(i)], order[static_cast<std::size_t>(j)]);
    }
    best.score = parent + 1e-9 * n;
    bool found = false;
    for (int k = 0; k < kTerrainFeatures; ++k) {
      if (k >= p_.features_per_split && found) break;
      const int f = order[static_cast<std::size_t>(k)];
      scratch_.clear();
      for (std::uint32_t i = begin; i < end; ++i) {
        scratch_.push_back({data_.features[idx_[i]][static_cast<std::size_t>(f)], data_.labels[idx_[i]]});
      }
      std::sort(scratch_.begin(), scratch_.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      std::array<double, kTerrainClasses> left{}, right{};
      for (int t = 0; t < kTerrainClasses; ++t) right[static_cast<std::size_t>(t)] = static_cast<double>(counts[static_cast<std::size_t>(t)]);
      double sum_left = 0.0, sum_right = parent * n;  // sums of squared class counts
      for (std::size_t i = 0; i + 1 < scratch_.size(); ++i) {
        const std::size_t c = scratch_[i].second;
        sum_left += 2.0 * left[c] + 1.0;
        sum_right -= 2.0 * right[c] - 1.0;
        left[c] += 1.0;
        right[c] -= 1.0;
        if (!(scratch_[i].first < scratch_[i + 1].first)) continue;
        const double nl = static_cast<double>(i + 1);
        const double score = sum_left / nl + sum_right / (n - nl);
        if (score > best.score) {
          const float a = scratch_[i].first, b = scratch_[i + 1].first;
          float t = a + 0.5f * (b - a);
          if (!(t < b) || !(t >= a)) t = a;
          best = {f, t, score};
          found = true;
        }
      }
    }
    return found;
  }

  std::uint32_t partition(std::uint32_t begin, std::uint32_t end, const Split& s) {
    auto it = std::partition(idx_.begin() + begin, idx_.begin() + end, [&](std::uint32_t i) {
      return data_.features[i][static_cast<std::size_t>(s.feature)] <= s.threshold;
    });
    return static_cast<std::uint32_t>(it - idx_.begin());
  }

  const LabelledFeatures& data_;
  const ForestParams& p_;
  Rng rng_;
  std::vector<std::uint32_t> idx_;
  std::vector<std::pair<float, std::uint8_t>> scratch_;
};

}  // namespace

std::string check_forest_params(const ForestParams& p) {
  if (p.trees < 1 || p.trees > 1000) return "trees must be 1 to 1000";
  if (p.features_per_split < 1 || p.features_per_split > kTerrainFeatures) {
    return "features per split must be 1 to " + std::to_string(kTerrainFeatures);
  }
  if (p.min_samples_split < 2) return "the minimum samples to split must be at least 2";
  if (p.max_depth < 0) return "max depth must be 0 (unlimited) or more";
  return {};
}

std::array<std::uint64_t, kTerrainClasses> LabelledFeatures::class_counts() const noexcept {
  std::array<std::uint64_t, kTerrainClasses> c{};
  for (auto l : labels) ++c[l];
  return c;
}

void LabelledFeatures::limit_per_class(std::size_t per_class, std::uint64_t seed) {
  std::array<std::size_t, kTerrainClasses> caps;
  caps.fill(per_class);
  limit_per_class(caps, seed);
}

void LabelledFeatures::limit_per_class(const std::array<std::size_t, kTerrainClasses>& caps, std::uint64_t seed) {
  Rng rng(seed);
  std::array<std::vector<std::uint32_t>, kTerrainClasses> members;
  for (std::size_t i = 0; i < labels.size(); ++i) members[labels[i]].push_back(static_cast<std::uint32_t>(i));
  std::vector<std::uint32_t> keep;
  for (std::size_t c = 0; c < members.size(); ++c) {
    auto& m = members[c];
    const std::size_t per_class = caps[c];
    if (per_class > 0 && m.size() > per_class) {
      for (std::size_t i = 0; i < per_class; ++i) std::swap(m[i], m[i + rng.below(m.size() - i)]);
      m.resize(per_class);
    }
    keep.insert(keep.end(), m.begin(), m.end());
  }
  std::sort(keep.begin(), keep.end());
  LabelledFeatures out;
  for (auto i : keep) {
    out.features.push_back(features[i]);
    out.labels.push_back(labels[i]);
  }
  *this = std::move(out);
}

std::uint64_t ConfusionMatrix::row_total(int truth) const noexcept {
  std::uint64_t s = 0;
  for (auto v : counts[static_cast<std::size_t>(truth)]) s += v;
  return s;
}
std::uint64_t ConfusionMatrix::total() const noexcept {
  std::uint64_t s = 0;
  for (int t = 0; t < kTerrainClasses; ++t) s += row_total(t);
  return s;
}
double ConfusionMatrix::rate(int truth, int predicted) const noexcept {
  const auto n = row_total(truth);
  return n ? static_cast<double>(counts[static_cast<std::size_t>(truth)][static_cast<std::size_t>(predicted)]) / static_cast<double>(n) : 0.0;
}
double ConfusionMatrix::accuracy() const noexcept {
  std::uint64_t hit = 0;
  for (int t = 0; t < kTerrainClasses; ++t) hit += counts[static_cast<std::size_t>(t)][static_cast<std::size_t>(t)];
  const auto n = total();
  return n ? static_cast<double>(hit) / static_cast<double>(n) : 0.0;
}

std::string format_confusion(const ConfusionMatrix& m, const ConfusionMatrix* bracketed) {
  const int width = bracketed ? 15 : 8;
  std::string out;
  char buf[64];
  std::snprintf(buf, sizeof buf, "%-12s", "true \\ est.");
  out += buf;
  for (int p = 0; p < kTerrainClasses; ++p) {
    std::snprintf(buf, sizeof buf, "%*s", width, std::string(terrain_class_name(static_cast<TerrainClass>(p))).c_str());
    out += buf;
  }
  out += "     cells\n";
  for (int t = 0; t < kTerrainClasses; ++t) {
    if (m.row_total(t) == 0) continue;
    std::snprintf(buf, sizeof buf, "%-12s", std::string(terrain_class_name(static_cast<TerrainClass>(t))).c_str());
    out += buf;
    for (int p = 0; p < kTerrainClasses; ++p) {
      if (bracketed) {
        std::snprintf(buf, sizeof buf, "%7.2f (%5.2f)", m.rate(t, p), bracketed->rate(t, p));
      } else {
        std::snprintf(buf, sizeof buf, "%8.2f", m.rate(t, p));
      }
      out += buf;
    }
    std::snprintf(buf, sizeof buf, "%10llu\n", static_cast<unsigned long long>(m.row_total(t)));
    out += buf;
  }
  std::snprintf(buf, sizeof buf, "accuracy %.3f over %llu cells\n", m.accuracy(), static_cast<unsigned long long>(m.total()));
  out += buf;
  return out;
}

TrainedForest train_forest(const LabelledFeatures& data, const ForestParams& params,
                           const std::function<void(double)>& progress) {
  TrainedForest result;
  if (std::string e = check_forest_params(params); !e.empty()) {
    result.error = e;
    return result;
  }
  if (data.size() < 2) {
    result.error = "no labelled cells to learn from";
    return result;
  }
  if (data.size() > (1u << 31)) {
    result.error = "too many samples";
    return result;
  }
  const auto classes = data.class_counts();
  if (std::count_if(classes.begin(), classes.end(), [](auto c) { return c > 0; }) < 2) {
    result.error = "the labelled cells hold fewer than two classes";
    return result;
  }
  std::vector<Tree> trees(static_cast<std::size_t>(params.trees));
  std::atomic<int> next{0};
  std::mutex progress_mutex;
  int done = 0;
  auto worker = [&] {
    for (int t = next++; t < params.trees; t = next++) {
      // Each tree's generator depends only on the seed and its number.
      TreeBuilder b(data, params, params.seed * std::uint64_t{0x2545F4914F6CDD1D} + static_cast<std::uint64_t>(t) + 1u);
      trees[static_cast<std::size_t>(t)] = b.build();
      if (progress) {
        std::lock_guard lock(progress_mutex);
        progress(static_cast<double>(++done) / params.trees);
      }
    }
  };
  int threads = params.threads > 0 ? params.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  threads = std::min(threads, params.trees);
  std::vector<std::thread> pool;
  for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
  worker();
  for (auto& th : pool) th.join();

  std::vector<std::uint32_t> roots;
  std::vector<ForestNode> nodes;
  std::vector<float> leaves;
  for (const Tree& tree : trees) {
    const auto base = static_cast<std::int32_t>(nodes.size());
    const auto leaf_base = static_cast<std::int32_t>(leaves.size() / kTerrainClasses);
    roots.push_back(static_cast<std::uint32_t>(base));
    for (ForestNode n : tree.nodes) {
      n.next += n.feature < 0 ? leaf_base : base;
      nodes.push_back(n);
    }
    leaves.insert(leaves.end(), tree.leaves.begin(), tree.leaves.end());
  }
  auto made = RandomForest::from_parts(std::move(roots), std::move(nodes), std::move(leaves));
  if (!made.forest) {
    result.error = "internal error: the grown forest is invalid: " + made.error;
    return result;
  }
  // Out-of-bag estimate.
  for (std::size_t i = 0; i < data.size(); ++i) {
    ClassDistribution sum{};
    int voters = 0;
    for (std::size_t t = 0; t < trees.size(); ++t) {
      if (trees[t].in_bag[i]) continue;
      const float* p = made.forest->tree_leaf(t, data.features[i]);
      for (int c = 0; c < kTerrainClasses; ++c) sum[static_cast<std::size_t>(c)] += p[c];
      ++voters;
    }
    if (voters == 0) continue;
    const auto best = static_cast<int>(std::max_element(sum.begin(), sum.end()) - sum.begin());
    result.out_of_bag.add(data.labels[i], best);
  }
  result.forest = std::move(made.forest);
  return result;
}

}  // namespace trailnav::perception
