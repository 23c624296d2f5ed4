#include "trailnav/perception/place/online.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

namespace trailnav::perception::place {
namespace {

std::size_t checked_capacity(std::size_t capacity) {
  if (capacity == 0) throw std::invalid_argument("place: a database capacity of 0 images");
  return capacity;
}

// The filter is sized for the capacity; until the database is finished it
// is never stepped.
}  // namespace

OnlinePlace::OnlinePlace(const OnlineConfig& config)
    : config_(config),
      hog_(config.hog, config.width, config.height),
      capacity_(checked_capacity(config.capacity)),
      codes_(capacity_ * static_cast<std::size_t>(hog_.length())),
      norms_(capacity_),
      column_sum_(capacity_),
      descriptor_(static_cast<std::size_t>(hog_.length())),
      query_code_(static_cast<std::size_t>(hog_.length())),
      row_(capacity_),
      filter_(capacity_, config.transition) {}

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
  return true;
}

PlaceEstimate OnlinePlace::step(std::span<const float> descriptor) noexcept {
  const auto len = static_cast<std::size_t>(hog_.length());
  if (count_ == 0 || descriptor.size() != len) return {};
  const float qn = encode_descriptor(descriptor, query_code_);
  float lo = 0.0f, hi = 0.0f;
  if (whitening_.rank > 0) {
    // q = s - mean; t = Uᵀ q; s̃ = base q + U (gains ⊙ t).
    const auto k = static_cast<std::size_t>(whitening_.rank);
    std::fill(projection_.begin(), projection_.end(), 0.0f);
    for (std::size_t j = 0; j < count_; ++j) {
      const float q = cosine(query_code_, qn, {codes_.data() + j * len, len}, norms_[j]) - whitening_.mean[j];
      row_[j] = q;
      const float* u = whitening_.directions.data() + j * k;
      for (std::size_t c = 0; c < k; ++c) projection_[c] += u[c] * q;
    }
    for (std::size_t c = 0; c < k; ++c) projection_[c] *= whitening_.gains[c];
    for (std::size_t j = 0; j < count_; ++j) {
      const float* u = whitening_.directions.data() + j * k;
      float v = whitening_.base * row_[j];
      for (std::size_t c = 0; c < k; ++c) v += u[c] * projection_[c];
      row_[j] = v;
      if (j == 0 || v < lo) lo = v;
      if (j == 0 || v > hi) hi = v;
    }
  } else {
    column_count_ += 1.0;
    const double inv_count = 1.0 / column_count_;
    for (std::size_t j = 0; j < count_; ++j) {
      const float sim = cosine(query_code_, qn, {codes_.data() + j * len, len}, norms_[j]);
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
  return {static_cast<int>(best), bel[best]};
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
