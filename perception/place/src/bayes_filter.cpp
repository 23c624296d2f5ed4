#include "trailnav/perception/place/bayes_filter.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace trailnav::perception::place {

BayesFilter::BayesFilter(std::size_t database_size, const TransitionModel& model, bool reversed)
    : model_(model), reversed_(reversed) {
  if (database_size == 0) throw std::invalid_argument("place filter: the database is empty");
  if (model.f < 1 || model.b < 1 || !(model.c_f > 0.0) || !(model.c_s > 0.0) || !(model.c_b > 0.0))
    throw std::invalid_argument("place filter: f and b must be at least 1 and c_f, c_s, c_b positive");
  const std::size_t n = database_size;
  belief_.resize(n);
  prefix_.resize(n + 1);
  // α: one for every source, the sum of a row that lies wholly inside the
  // database (n_D ones, plus c - 1 for each band position). A row near an
  // end has band positions outside; scaling it by its own smaller sum would
  // pile the mass those carry onto the last images (the end of the database
  // would hold the belief like a sink); with the common α that mass is lost
  // and the update's η restores the sum.
  const double alpha = static_cast<double>(n) + (model.c_f - 1.0) * (model.f - 1) + (model.c_s - 1.0) +
                       (model.c_b - 1.0) * (model.b - 1);
  inverse_alpha_ = 1.0 / alpha;
  reset();
}

void BayesFilter::reset() noexcept { std::fill(belief_.begin(), belief_.end(), 1.0 / static_cast<double>(belief_.size())); }

void BayesFilter::predict() noexcept {
  const std::size_t n = belief_.size();
  // prefix_[k] = Σ_{x' < k} Bel(x') / α(x')
  prefix_[0] = 0.0;
  for (std::size_t i = 0; i < n; ++i) prefix_[i + 1] = prefix_[i] + belief_[i] * inverse_alpha_;
  const double all = prefix_[n];
  const auto band = [&](long from, long to) {  // Σ over x' in [from, to], clipped to the database
    from = std::max(from, 0L);
    to = std::min(to, static_cast<long>(n) - 1);
    return from > to ? 0.0 : prefix_[static_cast<std::size_t>(to) + 1] - prefix_[static_cast<std::size_t>(from)];
  };
  const long f = model_.f, b = model_.b;
  for (std::size_t i = 0; i < n; ++i) {
    const long x = static_cast<long>(i);
    const double own = belief_[i] * inverse_alpha_;
    // Forward: x - x' in (0, f), the sources x' in [x - f + 1, x - 1]
    // (reversed: [x + 1, x + f - 1]); backward: x' - x in (0, b).
    const double fwd = reversed_ ? band(x + 1, x + f - 1) : band(x - f + 1, x - 1);
    const double back = reversed_ ? band(x - b + 1, x - 1) : band(x + 1, x + b - 1);
    belief_[i] = all + (model_.c_f - 1.0) * fwd + (model_.c_s - 1.0) * own + (model_.c_b - 1.0) * back;
  }
}

void BayesFilter::update(std::span<const float> likelihood) noexcept {
  const std::size_t n = belief_.size();
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) sum += belief_[i] * static_cast<double>(likelihood[i]);
  if (sum > 0.0 && std::isfinite(sum)) {
    const double inv = 1.0 / sum;
    for (std::size_t i = 0; i < n; ++i) belief_[i] *= static_cast<double>(likelihood[i]) * inv;
    return;
  }
  // Nothing observed: keep the prediction, normalised.
  sum = 0.0;
  for (double v : belief_) sum += v;
  const double inv = 1.0 / sum;
  for (double& v : belief_) v *= inv;
}

namespace {

using MatrixD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Beliefs in double: a product of two far-off beliefs (1e-30 each) is below
// float's range.
MatrixD pass(const Matrix& likelihood, const TransitionModel& model, bool reversed) {
  const Eigen::Index n_q = likelihood.rows();
  const Eigen::Index n_d = likelihood.cols();
  MatrixD out(n_q, n_d);
  BayesFilter filter(static_cast<std::size_t>(n_d), model, reversed);
  for (Eigen::Index k = 0; k < n_q; ++k) {
    const Eigen::Index i = reversed ? n_q - 1 - k : k;
    filter.step({likelihood.row(i).data(), static_cast<std::size_t>(n_d)});
    const std::span<const double> bel = filter.belief();
    for (Eigen::Index j = 0; j < n_d; ++j) out(i, j) = bel[static_cast<std::size_t>(j)];
  }
  return out;
}

}  // namespace

Matrix forward_pass(const Matrix& likelihood, const TransitionModel& model) {
  return pass(likelihood, model, false).cast<float>();
}

Matrix forward_backward(const Matrix& likelihood, const TransitionModel& model) {
  MatrixD b = pass(likelihood, model, false);
  b = (b.array() * pass(likelihood, model, true).array()).sqrt().matrix();  // Eq. 5.9
  for (Eigen::Index i = 0; i < b.rows(); ++i) {
    const double sum = b.row(i).sum();
    if (sum > 0.0) b.row(i) /= sum;
  }
  return b.cast<float>();
}

}  // namespace trailnav::perception::place
