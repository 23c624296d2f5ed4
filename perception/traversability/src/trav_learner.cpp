#include "trailnav/perception/trav_learner.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <boost/math/distributions/chi_squared.hpp>

namespace trailnav::perception::trav {
namespace {

double logit(double p) noexcept { return std::log(p / (1.0 - p)); }

std::uint32_t saturated_add(std::uint32_t a, std::uint64_t b) noexcept {
  const std::uint64_t s = static_cast<std::uint64_t>(a) + b;
  return s > std::numeric_limits<std::uint32_t>::max() ? std::numeric_limits<std::uint32_t>::max()
                                                       : static_cast<std::uint32_t>(s);
}

}  // namespace

// --- WordCounts ---

WordCounts::WordCounts(std::uint32_t vocabulary) : p_(vocabulary, 0), u_(vocabulary, 0) {}

void WordCounts::add(std::uint32_t word, bool positive, std::uint32_t count) noexcept {
  if (word >= p_.size()) return;
  auto& slot = positive ? p_[word] : u_[word];
  const std::uint32_t before = slot;
  slot = saturated_add(slot, count);
  (positive ? np_ : nu_) += slot - before;
}

void WordCounts::add(const WordCounts& other) noexcept {
  const std::size_t n = std::min(p_.size(), other.p_.size());
  for (std::size_t w = 0; w < n; ++w) {
    if (other.p_[w] != 0) add(static_cast<std::uint32_t>(w), true, other.p_[w]);
    if (other.u_[w] != 0) add(static_cast<std::uint32_t>(w), false, other.u_[w]);
  }
}

void WordCounts::clear() noexcept {
  std::fill(p_.begin(), p_.end(), 0u);
  std::fill(u_.begin(), u_.end(), 0u);
  np_ = nu_ = 0;
}

// --- config, test ---

std::string check_learner(const LearnerConfig& c) {
  if (!(c.alpha_p >= 0.0) || !std::isfinite(c.alpha_p)) return "alpha_p must be 0 (1/|V|) or positive";
  if (!(c.alpha_n > 0.0) || !std::isfinite(c.alpha_n)) return "alpha_n must be positive";
  if (!(c.epsilon > 0.0 && c.epsilon < 0.5)) return "epsilon must lie in (0, 0.5)";
  if (!(c.chi2_alpha > 0.0 && c.chi2_alpha < 1.0)) return "chi2_alpha must lie in (0, 1)";
  if (!(c.min_expected >= 0.0) || !std::isfinite(c.min_expected)) return "min_expected must be 0 or positive";
  if (c.max_models < 1 || c.max_models > kMaxModels) return "max_models must be 1 to " + std::to_string(kMaxModels);
  if (!(c.prior == 0.0 || (c.prior > 0.0 && c.prior < 1.0))) return "prior must be 0 (estimated) or lie in (0, 1)";
  return "";
}

std::string_view method_name(Method m) noexcept { return m == Method::pnb ? "PNB" : "POS"; }

ChiSquare chi_square_homogeneity(std::span<const std::uint32_t> a, std::span<const std::uint32_t> b,
                                 double min_expected) noexcept {
  ChiSquare out;
  const std::size_t n = std::min(a.size(), b.size());
  double na = 0.0, nb = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    na += a[k];
    nb += b[k];
  }
  if (na == 0.0 || nb == 0.0) return out;
  const double total = na + nb, fa = na / total, fb = nb / total;
  double stat = 0.0, pool_a = 0.0, pool_b = 0.0;
  int columns = 0;
  auto column = [&](double oa, double ob) {
    const double t = oa + ob, ea = fa * t, eb = fb * t;
    stat += (oa - ea) * (oa - ea) / ea + (ob - eb) * (ob - eb) / eb;
    ++columns;
  };
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(a[k]) + b[k];
    if (t == 0.0) continue;
    if (std::min(fa, fb) * t < min_expected) {
      pool_a += a[k];
      pool_b += b[k];
    } else {
      column(a[k], b[k]);
    }
  }
  if (pool_a + pool_b > 0.0) column(pool_a, pool_b);
  out.statistic = stat;
  out.dof = columns - 1;
  if (out.dof < 1) return out;
  out.p_value = boost::math::cdf(boost::math::complement(boost::math::chi_squared(out.dof), stat));
  return out;
}

// --- TravModels ---

TravModels::TravModels(const Vocabulary& vocabulary, const LearnerConfig& config)
    : vocabulary_(vocabulary), config_(config) {
  const std::size_t v = vocabulary_.size(), m = config_.max_models;
  counts_.reserve(m);
  for (std::size_t i = 0; i < m; ++i) counts_.emplace_back(static_cast<std::uint32_t>(v));
  pnb_llr_.assign(m * v, 0.0f);
  pos_p_.assign(m * v, 0.0f);
  pos_llr_.assign(v, 0.0f);
  pnb_prior_.assign(m, 0.5);
  c_.assign(m, 1.0);
  pnb_prior_logit_.assign(m, 0.0f);
  labelled_share_.assign(m, 0.0);
}

TravModels::Assignment TravModels::train(const WordCounts& local_map) noexcept {
  Assignment a;
  if (local_map.total_positive() == 0 || local_map.vocabulary() != vocabulary_.size()) return a;
  int best = -1;
  ChiSquare best_test;
  for (std::uint32_t m = 0; m < models_; ++m) {
    const ChiSquare t = chi_square_homogeneity(local_map.positives(), counts_[m].positives(), config_.min_expected);
    if (best < 0 || t.p_value > best_test.p_value) {
      best = static_cast<int>(m);
      best_test = t;
    }
  }
  if (best >= 0 && best_test.p_value >= config_.chi2_alpha) {
    a.model = best;
    a.test = best_test;
  } else if (models_ < config_.max_models) {
    a.model = static_cast<int>(models_++);
    a.created = true;
  } else {
    a.model = best;
    a.test = best_test;
    a.forced = true;
  }
  counts_[static_cast<std::size_t>(a.model)].add(local_map);
  refresh(static_cast<std::uint32_t>(a.model));
  refresh_pos();
  return a;
}

void TravModels::set_models(std::span<const WordCounts> models) {
  models_ = static_cast<std::uint32_t>(std::min<std::size_t>(models.size(), config_.max_models));
  for (std::uint32_t m = 0; m < config_.max_models; ++m) counts_[m].clear();
  for (std::uint32_t m = 0; m < models_; ++m) {
    counts_[m].add(models[m]);
    refresh(m);
  }
  refresh_pos();
}

void TravModels::refresh(std::uint32_t m) noexcept {
  const WordCounts& k = counts_[m];
  const std::size_t v = vocabulary_.size();
  const double size = static_cast<double>(v);
  const double np = static_cast<double>(k.total_positive()), nu = static_cast<double>(k.total_unlabelled());

  // Elkan–Noto first (its estimate gives PNB's prior): g(f) = P(label | f), a
  // naive Bayes smoothed as PNB is (α_p labelled, α_n unlabelled, so a word
  // never seen is more likely unlabelled: Eq. 6.11's rule of safety); c the
  // largest g over labelled words.
  const double alpha_p = config_.alpha_p > 0.0 ? config_.alpha_p : 1.0 / size;
  const double alpha_n = config_.alpha_n;
  float* pos = &pos_p_[m * v];
  const double p_label = np + nu > 0.0 ? np / (np + nu) : 0.0;
  double c = 0.0;
  for (std::size_t w = 0; w < v; ++w) {
    const double pl = (alpha_p + k.positive(static_cast<std::uint32_t>(w))) / (alpha_p * size + np);
    const double pu = (alpha_n + k.unlabelled(static_cast<std::uint32_t>(w))) / (alpha_n * size + nu);
    const double g = p_label * pl / (p_label * pl + (1.0 - p_label) * pu);
    pos[w] = static_cast<float>(g);
    if (k.positive(static_cast<std::uint32_t>(w)) >= kCSupport) c = std::max(c, g);
  }
  if (!(c > 0.0)) {  // no word seen that often: every labelled word
    for (std::size_t w = 0; w < v; ++w) {
      if (k.positive(static_cast<std::uint32_t>(w)) > 0) c = std::max(c, static_cast<double>(pos[w]));
    }
  }
  if (!(c > 0.0)) c = 1.0;
  c_[m] = c;
  // For the prior, Elkan–Noto's e1: the mean of g over the labelled words.
  // The largest g (the classifier's c, as the thesis asks) rests on the
  // rarest words and made every unlabelled word look untraversable: priors
  // of 0.04–0.46 on a demonstration whose unlabelled ground was mostly
  // meadow the large robot may cross (docs/traversability.md).
  double e1 = 0.0;
  for (std::size_t w = 0; w < v; ++w) e1 += static_cast<double>(pos[w]) * k.positive(static_cast<std::uint32_t>(w));
  e1 = np > 0.0 ? e1 / np : 1.0;
  if (!(e1 > 0.0)) e1 = 1.0;
  const double eps = config_.epsilon;
  double traversable_unlabelled = 0.0;
  for (std::size_t w = 0; w < v; ++w) {
    const double g = pos[w];
    // The weight of an unlabelled word being positive, (1−e1)/e1 · g/(1−g), at most 1.
    const double weight = std::min(1.0, (1.0 - e1) / e1 * g / std::max(1.0 - g, 1e-12));
    traversable_unlabelled += weight * k.unlabelled(static_cast<std::uint32_t>(w));
    pos[w] = static_cast<float>(std::clamp(g / c, eps, 1.0 - eps));  // Eq. 6.13, 6.14
  }
  labelled_share_[m] = np + traversable_unlabelled;
  const double estimated = nu > 0.0 ? std::clamp(traversable_unlabelled / nu, 0.01, 0.99) : 0.5;
  const double prior = config_.prior > 0.0 ? config_.prior : estimated;
  pnb_prior_[m] = prior;
  pnb_prior_logit_[m] = static_cast<float>(logit(prior));

  // PNB (Eq. 6.7–6.10).
  const double pos_den = alpha_p * size + np;
  double cn_sum = 0.0;
  for (std::size_t w = 0; w < v; ++w) {
    const double p_trav = (alpha_p + k.positive(static_cast<std::uint32_t>(w))) / pos_den;
    cn_sum += std::max(0.0, std::floor(k.unlabelled(static_cast<std::uint32_t>(w)) - p_trav * prior * nu));
  }
  const double neg_mass = (1.0 - prior) * nu;
  const double eta = cn_sum > 0.0 ? neg_mass / cn_sum : 0.0;  // Eq. 6.10
  const double neg_den = alpha_n * size + neg_mass;
  float* llr = &pnb_llr_[m * v];
  for (std::size_t w = 0; w < v; ++w) {
    const double p_trav = (alpha_p + k.positive(static_cast<std::uint32_t>(w))) / pos_den;  // Eq. 6.7
    const double cn = std::max(0.0, std::floor(k.unlabelled(static_cast<std::uint32_t>(w)) - p_trav * prior * nu));  // 6.8
    const double p_not = (alpha_n + eta * cn) / neg_den;  // Eq. 6.9
    llr[w] = static_cast<float>(std::log(p_trav) - std::log(p_not));
  }
}

void TravModels::refresh_pos() noexcept {
  const std::size_t v = vocabulary_.size();
  // The prior: Elkan–Noto's traversable share of all words over the models.
  double traversable = 0.0, all = 0.0;
  for (std::uint32_t m = 0; m < models_; ++m) {
    traversable += labelled_share_[m];
    all += static_cast<double>(counts_[m].total_positive() + counts_[m].total_unlabelled());
  }
  pos_prior_ = all > 0.0 ? std::clamp(traversable / all, 0.01, 0.99) : 0.5;
  pos_prior_logit_ = static_cast<float>(logit(pos_prior_));
  for (std::size_t w = 0; w < v; ++w) {
    double best = config_.epsilon;
    for (std::uint32_t m = 0; m < models_; ++m) best = std::max(best, static_cast<double>(pos_p_[m * v + w]));  // Eq. 6.17
    pos_llr_[w] = static_cast<float>(logit(best) - logit(pos_prior_));
  }
}

double TravModels::probability(Method method, std::span<const std::uint32_t> words) const noexcept {
  if (models_ == 0) return 0.0;
  const std::uint32_t v = vocabulary_.size();
  if (method == Method::pos) {
    auto l = static_cast<double>(pos_prior_logit_);
    for (std::uint32_t w : words) {
      if (w < v) l += static_cast<double>(pos_llr_[w]);
    }
    return 1.0 / (1.0 + std::exp(-l));
  }
  double best = 0.0;
  for (std::uint32_t m = 0; m < models_; ++m) {
    auto l = static_cast<double>(pnb_prior_logit_[m]);
    for (std::uint32_t w : words) {
      if (w < v) l += static_cast<double>(pnb_llr_[static_cast<std::size_t>(m) * v + w]);
    }
    best = std::max(best, 1.0 / (1.0 + std::exp(-l)));  // Eq. 6.16
  }
  return best;
}

}  // namespace trailnav::perception::trav
