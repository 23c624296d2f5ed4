#include "trailnav/perception/place/online.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

namespace trailnav::perception::place {
namespace {

std::size_t checked_capacity(const OnlineConfig& c) {
  if (c.capacity == 0) throw std::invalid_argument("place: a database capacity of 0 images");
  if (c.lag < 0) throw std::invalid_argument("place: a negative lag");
  if (c.sequence.min_length < 0 || c.sequence.row_gap < 1 || c.sequence.column_gap < 0)
    throw std::invalid_argument("place: the sequence test needs a length of at least 0, a row gap of at least 1 and a column gap of at least 0");
  if (c.peaks_per_row < 1 || c.peaks_per_row > 16) throw std::invalid_argument("place: peaks_per_row must be 1 to 16");
  if (c.peak_radius < 0) throw std::invalid_argument("place: a negative peak radius");
  return c.capacity;
}

// The filter is sized for the capacity; until the database is finished it
// is never stepped.
}  // namespace

OnlinePlace::OnlinePlace(const OnlineConfig& config)
    : config_(config),
      hog_(config.hog, config.width, config.height),
      capacity_(checked_capacity(config)),
      codes_(capacity_ * static_cast<std::size_t>(hog_.length())),
      norms_(capacity_),
      column_sum_(capacity_),
      descriptor_(static_cast<std::size_t>(hog_.length())),
      query_code_(static_cast<std::size_t>(hog_.length())),
      row_(capacity_),
      filter_(capacity_, config.transition),
      slots_(static_cast<std::size_t>(config.lag) + 1),
      rows_(slots_ * capacity_),
      forward_(slots_ * capacity_),
      backward_(capacity_, config.transition, true),
      smoothed_(capacity_),
      ahead_(slots_ * static_cast<std::size_t>(config.peaks_per_row)),
      ahead_count_(slots_),
      history_(static_cast<std::size_t>(config.sequence.row_gap + 1) * static_cast<std::size_t>(config.peaks_per_row)),
      history_count_(static_cast<std::size_t>(config.sequence.row_gap + 1)) {}

bool OnlinePlace::add_database(std::span<const float> descriptor) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ >= capacity_ || descriptor.size() != len) return false;
  norms_[count_] = encode_descriptor(descriptor, {codes_.data() + count_ * len, len});
  ++count_;
  return true;
}

bool OnlinePlace::add_database_code(std::span<const std::uint8_t> code, float norm) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ >= capacity_ || code.size() != len) return false;
  std::copy(code.begin(), code.end(), codes_.begin() + static_cast<long>(count_ * len));
  norms_[count_] = norm;
  ++count_;
  return true;
}

void OnlinePlace::finish_database() noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  // The priors: each image's mean similarity to the others (O(n_D²), once).
  std::fill(column_sum_.begin(), column_sum_.end(), 0.0);
  for (std::size_t j = 0; j < count_; ++j) {
    double sum = 0.0;
    for (std::size_t k = 0; k < count_; ++k) {
      if (k == j) continue;
      sum += static_cast<double>(cosine({codes_.data() + j * len, len}, norms_[j], {codes_.data() + k * len, len}, norms_[k]));
    }
    const double mean = count_ > 1 ? sum / static_cast<double>(count_ - 1) : 1.0;
    column_sum_[j] = mean * config_.prior_queries;
  }
  column_count_ = config_.prior_queries;
  filter_ = BayesFilter(std::max<std::size_t>(count_, 1), config_.transition);
  backward_ = BayesFilter(std::max<std::size_t>(count_, 1), config_.transition, true);
  steps_ = 0;
  lagged_ = {};
  std::fill(ahead_count_.begin(), ahead_count_.end(), 0);
  std::fill(history_count_.begin(), history_count_.end(), 0);
}

std::span<const float> OnlinePlace::describe(std::span<const std::uint8_t> grey, int stride) noexcept {
  hog_.compute(grey, stride, descriptor_);
  return descriptor_;
}

bool OnlinePlace::set_whitening(const Whitening& w) {
  if (w.rank <= 0) {
    whitening_ = {};
    return true;
  }
  if (w.mean.size() != count_ || w.gains.size() != static_cast<std::size_t>(w.rank) ||
      w.directions.size() != count_ * static_cast<std::size_t>(w.rank))
    return false;
  whitening_ = w;
  projection_.assign(static_cast<std::size_t>(w.rank), 0.0f);
  // The directions as bytes, each direction scaled by its largest value:
  // a quarter of the memory a step streams (docs/place.md "ZCA for the robot").
  const auto k = static_cast<std::size_t>(w.rank);
  direction_scale_.assign(k, 0.0f);
  for (std::size_t j = 0; j < count_; ++j)
    for (std::size_t c = 0; c < k; ++c) direction_scale_[c] = std::max(direction_scale_[c], std::abs(w.directions[j * k + c]));
  for (float& v : direction_scale_) v = v > 0.0f ? v / 127.0f : 1.0f;
  directions_q_.resize(count_ * k);
  for (std::size_t j = 0; j < count_; ++j)
    for (std::size_t c = 0; c < k; ++c)
      directions_q_[j * k + c] = static_cast<std::int8_t>(std::lround(w.directions[j * k + c] / direction_scale_[c]));
  whitening_.directions.clear();
  whitening_.directions.shrink_to_fit();
  return true;
}

PlaceEstimate OnlinePlace::step(std::span<const float> descriptor) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ == 0 || descriptor.size() != len) return {};
  const float qn = encode_descriptor(descriptor, query_code_);
  for (std::size_t j = 0; j < count_; ++j) row_[j] = cosine(query_code_, qn, {codes_.data() + j * len, len}, norms_[j]);
  return advance();
}

PlaceEstimate OnlinePlace::step_similarities(std::span<const float> similarities) noexcept {
  if (count_ == 0 || similarities.size() != count_) return {};
  std::copy(similarities.begin(), similarities.end(), row_.begin());
  return advance();
}

PlaceEstimate OnlinePlace::advance() noexcept {
  float lo = 0.0f, hi = 0.0f;
  if (whitening_.rank > 0) {
    // q = s - mean; t = Uᵀ q; s̃ = base q + U (gains ⊙ t).
    const auto k = static_cast<std::size_t>(whitening_.rank);
    // U stored as bytes: U = Q diag(scale); t = scale ⊙ gains ⊙ (Qᵀ q).
    std::fill(projection_.begin(), projection_.end(), 0.0f);
    for (std::size_t j = 0; j < count_; ++j) {
      const float q = row_[j] - whitening_.mean[j];
      row_[j] = q;
      const std::int8_t* u = directions_q_.data() + j * k;
      for (std::size_t c = 0; c < k; ++c) projection_[c] += static_cast<float>(u[c]) * q;
    }
    for (std::size_t c = 0; c < k; ++c) projection_[c] *= whitening_.gains[c] * direction_scale_[c] * direction_scale_[c];
    for (std::size_t j = 0; j < count_; ++j) {
      const std::int8_t* u = directions_q_.data() + j * k;
      // The dot product in eight lanes (the compiler keeps them in one
      // vector register; a single sum it may not reorder).
      std::array<float, 8> lanes{};
      std::size_t c = 0;
      for (; c + 8 <= k; c += 8)
        for (std::size_t l = 0; l < 8; ++l) lanes[l] += static_cast<float>(u[c + l]) * projection_[c + l];
      float v = whitening_.base * row_[j];
      for (; c < k; ++c) v += static_cast<float>(u[c]) * projection_[c];
      for (const float lane : lanes) v += lane;
      row_[j] = v;
      if (j == 0 || v < lo) lo = v;
      if (j == 0 || v > hi) hi = v;
    }
  } else {
    column_count_ += 1.0;
    const double inv_count = 1.0 / column_count_;
    for (std::size_t j = 0; j < count_; ++j) {
      const float sim = row_[j];
      column_sum_[j] += static_cast<double>(sim);
      const double mean = column_sum_[j] * inv_count;
      const float v = mean > 0.0 ? static_cast<float>(static_cast<double>(sim) / mean) : 0.0f;  // Eq. 5.3
      row_[j] = v;
      if (j == 0 || v < lo) lo = v;
      if (j == 0 || v > hi) hi = v;
    }
  }
  const float range = hi - lo;
  for (std::size_t j = 0; j < count_; ++j) row_[j] = range > 0.0f ? (row_[j] - lo) / range : 1.0f;  // Eq. 5.4
  filter_.step({row_.data(), count_});
  const std::span<const double> bel = filter_.belief();
  std::size_t best = 0;
  for (std::size_t j = 1; j < count_; ++j)
    if (bel[j] > bel[best]) best = j;
  smooth_and_test();
  return {static_cast<int>(best), bel[best]};
}

int OnlinePlace::find_peaks(std::span<const double> belief, Peak* out) const noexcept {
  // Greedy: the largest belief at or above 1/n_D outside ±radius of those
  // taken, peaks_per_row times. `taken` is kept sorted by column, so each
  // pass scans the gaps between the excluded intervals.
  const long n = static_cast<long>(count_);
  const long radius = config_.peak_radius;
  const double uniform = 1.0 / static_cast<double>(count_);
  std::array<long, 16> taken{};
  int found = 0;
  for (int pass = 0; pass < config_.peaks_per_row; ++pass) {
    long best = -1;
    long from = 0;
    for (int k = 0; k <= found; ++k) {
      const long to = k < found ? taken[static_cast<std::size_t>(k)] - radius : n;  // exclusive
      for (long j = from; j < to; ++j)
        if (belief[static_cast<std::size_t>(j)] >= uniform &&
            (best < 0 || belief[static_cast<std::size_t>(j)] > belief[static_cast<std::size_t>(best)]))
          best = j;
      if (k < found) from = std::max(from, taken[static_cast<std::size_t>(k)] + radius + 1);
    }
    if (best < 0) break;
    int at = found;
    while (at > 0 && taken[static_cast<std::size_t>(at - 1)] > best) {
      taken[static_cast<std::size_t>(at)] = taken[static_cast<std::size_t>(at - 1)];
      --at;
    }
    taken[static_cast<std::size_t>(at)] = best;
    out[found] = {static_cast<int>(best), 1};
    ++found;
  }
  return found;
}

void OnlinePlace::smooth_and_test() noexcept {
  const std::size_t cap = capacity_;
  const auto per_row = static_cast<std::size_t>(config_.peaks_per_row);
  const std::uint64_t t = steps_++;
  const std::size_t slot = t % slots_;
  std::copy(row_.begin(), row_.begin() + static_cast<long>(count_), rows_.begin() + static_cast<long>(slot * cap));
  const std::span<const double> fwd = filter_.belief();
  std::copy(fwd.begin(), fwd.begin() + static_cast<long>(count_), forward_.begin() + static_cast<long>(slot * cap));
  ahead_count_[slot] = find_peaks(fwd, ahead_.data() + slot * per_row);
  const auto lag = static_cast<std::uint64_t>(config_.lag);
  if (t < lag) {
    lagged_ = {};
    return;
  }
  const std::uint64_t r = t - lag;
  const double* f = forward_.data() + (r % slots_) * cap;
  if (lag == 0) {
    std::copy(f, f + count_, smoothed_.begin());
  } else {
    // The backward pass over rows t ... r from a uniform belief at t, and
    // Eq. 5.9: √(B_f B_b), normalised.
    backward_.reset();
    for (std::uint64_t s = t + 1; s-- > r;) backward_.step({rows_.data() + (s % slots_) * cap, count_});
    const std::span<const double> b = backward_.belief();
    double sum = 0.0;
    for (std::size_t j = 0; j < count_; ++j) {
      smoothed_[j] = std::sqrt(f[j] * b[j]);
      sum += smoothed_[j];
    }
    if (sum > 0.0) {
      const double inv = 1.0 / sum;
      for (std::size_t j = 0; j < count_; ++j) smoothed_[j] *= inv;
    }
  }
  // The smoothed row's peaks and the longest chains ending at them through
  // the answered rows before (g_r back).
  const int g_r = config_.sequence.row_gap, g_c = config_.sequence.column_gap;
  const auto hist_rows = static_cast<std::uint64_t>(g_r + 1);
  const std::size_t hslot = r % hist_rows;
  Peak* mine = history_.data() + hslot * per_row;
  const int found = find_peaks({smoothed_.data(), count_}, mine);
  history_count_[hslot] = found;
  for (int k = 0; k < found; ++k) {
    for (std::uint64_t gap = 1; gap <= static_cast<std::uint64_t>(g_r) && gap <= r; ++gap) {
      const std::size_t other = (r - gap) % hist_rows;
      const Peak* p = history_.data() + other * per_row;
      for (int m = 0; m < history_count_[other]; ++m)
        if (std::abs(p[m].column - mine[k].column) <= g_c) mine[k].length = std::max(mine[k].length, p[m].length + 1);
    }
  }
  // The longest chains starting in the look-ahead rows (the forward
  // beliefs' peaks of r + 1 ... t), from the newest back.
  for (std::uint64_t s = t; s > r; --s) {
    Peak* p = ahead_.data() + (s % slots_) * per_row;
    for (int k = 0; k < ahead_count_[s % slots_]; ++k) {
      p[k].length = 1;
      for (std::uint64_t u = s + 1; u <= t && u <= s + static_cast<std::uint64_t>(g_r); ++u) {
        const Peak* q = ahead_.data() + (u % slots_) * per_row;
        for (int m = 0; m < ahead_count_[u % slots_]; ++m)
          if (std::abs(q[m].column - p[k].column) <= g_c) p[k].length = std::max(p[k].length, q[m].length + 1);
      }
    }
  }
  // The answer: the smoothed belief's largest, the first peak taken.
  LaggedEstimate& e = lagged_;
  e = {};
  e.valid = true;
  e.step = r;
  if (found == 0) return;
  e.index = mine[0].column;
  e.probability = smoothed_[static_cast<std::size_t>(e.index)];
  int starting = 1;
  for (std::uint64_t u = r + 1; u <= t && u <= r + static_cast<std::uint64_t>(g_r); ++u) {
    const Peak* q = ahead_.data() + (u % slots_) * per_row;
    for (int m = 0; m < ahead_count_[u % slots_]; ++m)
      if (std::abs(q[m].column - e.index) <= g_c) starting = std::max(starting, q[m].length + 1);
  }
  e.chain = mine[0].length + starting - 1;
  e.in_sequence = e.chain >= config_.sequence.min_length;
}

Whitening learn_whitening(std::span<const std::uint8_t> codes, std::span<const float> norms, int length, int rank,
                          double epsilon_relative, int full_solve_up_to) {
  using MatrixD = Eigen::MatrixXd;
  Whitening w;
  const auto n = static_cast<Eigen::Index>(norms.size());
  const auto len = static_cast<std::size_t>(length);
  if (n < 2 || rank <= 0) return w;
  rank = static_cast<int>(std::min<Eigen::Index>(rank, n - 1));
  // Ŝ: the database against itself, columns centred.
  MatrixD s(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = i; j < n; ++j) {
      const double v = static_cast<double>(cosine({codes.data() + static_cast<std::size_t>(i) * len, len}, norms[static_cast<std::size_t>(i)],
                                                  {codes.data() + static_cast<std::size_t>(j) * len, len}, norms[static_cast<std::size_t>(j)]));
      s(i, j) = v;
      s(j, i) = v;
    }
  const Eigen::RowVectorXd mean = s.colwise().mean();
  s.rowwise() -= mean;
  const double rows = static_cast<double>(n);
  // The mean eigenvalue of Σ = ŜᵀŜ / n is its trace over n.
  const double epsilon = epsilon_relative * s.squaredNorm() / rows / rows;
  Eigen::VectorXd lambda;
  MatrixD u;
  if (n <= full_solve_up_to) {
    const MatrixD sigma = s.transpose() * s / rows;
    Eigen::SelfAdjointEigenSolver<MatrixD> eig(sigma);  // ascending
    lambda = eig.eigenvalues().tail(rank).reverse();
    u = eig.eigenvectors().rightCols(rank).rowwise().reverse();
  } else {
    // Randomised subspace iteration (Halko, Martinsson and Tropp): Σ applied
    // as Ŝᵀ(Ŝ X) / n, four passes, a fixed seed.
    const Eigen::Index p = rank + 10;
    std::uint64_t state = 0x9E3779B97F4A7C15ull;
    MatrixD q(n, p);
    for (Eigen::Index i = 0; i < q.size(); ++i) {
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      q.data()[i] = static_cast<double>(state >> 11) / 9007199254740992.0 - 0.5;
    }
    for (int pass = 0; pass < 4; ++pass) {
      const MatrixD y = s.transpose() * (s * q) / rows;
      q = Eigen::HouseholderQR<MatrixD>(y).householderQ() * MatrixD::Identity(n, p);
    }
    const MatrixD b = q.transpose() * (s.transpose() * (s * q)) / rows;
    Eigen::SelfAdjointEigenSolver<MatrixD> eig(b);
    lambda = eig.eigenvalues().tail(rank).reverse();
    u = q * eig.eigenvectors().rightCols(rank).rowwise().reverse();
  }
  w.rank = rank;
  w.epsilon_relative = static_cast<float>(epsilon_relative);
  w.base = static_cast<float>(1.0 / std::sqrt(epsilon));
  w.mean.resize(static_cast<std::size_t>(n));
  for (Eigen::Index j = 0; j < n; ++j) w.mean[static_cast<std::size_t>(j)] = static_cast<float>(mean(j));
  w.gains.resize(static_cast<std::size_t>(rank));
  for (int c = 0; c < rank; ++c)
    w.gains[static_cast<std::size_t>(c)] =
        static_cast<float>(1.0 / std::sqrt(std::max(lambda(c), 0.0) + epsilon) - 1.0 / std::sqrt(epsilon));
  w.directions.resize(static_cast<std::size_t>(n) * static_cast<std::size_t>(rank));
  for (Eigen::Index j = 0; j < n; ++j)
    for (int c = 0; c < rank; ++c)
      w.directions[static_cast<std::size_t>(j) * static_cast<std::size_t>(rank) + static_cast<std::size_t>(c)] =
          static_cast<float>(u(j, c));
  return w;
}

}  // namespace trailnav::perception::place
