// Learning traversability from positive and unlabelled words (thesis §6.3):
// the Positive Naive Bayes of Denis et al. (Eq. 6.7–6.12), the Elkan–Noto
// classifier (Eq. 6.13–6.15) and terrain models chosen by Pearson's χ² test
// (Eq. 6.16–6.17), trained sequentially, one local map at a time, so that a
// model can be extended later. Every table is sized at construction for the
// configured vocabulary and number of terrain models; train() allocates
// nothing.
//
// Our decisions where the thesis leaves a value open (docs/traversability.md):
// - P(trav), the class prior of PNB, is not given. By default each terrain
//   model takes Elkan and Noto's estimate of the traversable share of its
//   unlabelled words, Σ_U w(f) / C(U) with w(f) = (1−e1)/e1 · g(f)/(1−g(f))
//   (their weight of an unlabelled example being positive), clamped to
//   [0.01, 0.99]; `prior` in the config fixes it instead.
// - Eq. 6.15 as printed adds the previous logit twice; we use the standard
//   static-state update l_n = l_{n−1} + logit P(trav|f_n) − logit P(trav),
//   l_0 = logit P(trav), with P(trav) Elkan–Noto's estimate of the
//   traversable share of all words (labelled and not).
// - g(f) = P(label|f) is a naive Bayes over the words, smoothed as PNB is
//   (α_p for the labelled, α_n for the unlabelled: a word never seen is more
//   likely unlabelled, the safety rule of Eq. 6.11; with Laplace smoothing on
//   both an unseen word came out traversable), and c is the largest g over the
//   words with at least kCSupport labelled examples (Elkan–Noto's e3, "the
//   most conservative", over words whose g is measured rather than guessed:
//   a word seen once as positive and never unlabelled has g near 0.5 from
//   the smoothing alone, and with it as c the large robot called a third of
//   the meadow traversable). P(trav|f) is clamped to [ε, 1−ε] (Eq. 6.14
//   clamps the top; the bottom keeps logits finite).
// - PNB's prior uses Elkan–Noto's e1 instead, the mean of g over the
//   labelled words: the largest g made every unlabelled word look
//   untraversable (priors of 0.04–0.46 where most unlabelled ground was
//   meadow the large robot may cross).
// - The χ² test compares the local map's positive words with each model's
//   (the terrain models separate the kinds of ground driven on, which is
//   what an unbalanced demonstration confuses, §6.3.3). Words expected fewer
//   than `min_expected` times in either histogram are pooled into one
//   column, as Pearson's approximation needs. A local map goes to the model
//   with the largest p-value ≥ α; if none, to a new model; once `max_models`
//   exist, to the one with the largest p-value (counted as forced).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "trailnav/perception/trav_vocabulary.hpp"

namespace trailnav::perception::trav {

// Words counted by label: positive (a feature of a cell the robot's
// footprint crossed in this local map) and unlabelled (all others).
class WordCounts {
 public:
  explicit WordCounts(std::uint32_t vocabulary = 0);

  std::uint32_t vocabulary() const noexcept { return static_cast<std::uint32_t>(p_.size()); }
  // Counts saturate at 2^32 − 1.
  void add(std::uint32_t word, bool positive, std::uint32_t count = 1) noexcept;
  void add(const WordCounts& other) noexcept;  // same vocabulary
  void clear() noexcept;

  std::uint32_t positive(std::uint32_t word) const noexcept { return p_[word]; }
  std::uint32_t unlabelled(std::uint32_t word) const noexcept { return u_[word]; }
  std::span<const std::uint32_t> positives() const noexcept { return p_; }
  std::span<const std::uint32_t> unlabelled_words() const noexcept { return u_; }
  std::uint64_t total_positive() const noexcept { return np_; }
  std::uint64_t total_unlabelled() const noexcept { return nu_; }

 private:
  std::vector<std::uint32_t> p_, u_;
  std::uint64_t np_ = 0, nu_ = 0;
};

struct LearnerConfig {
  double alpha_p = 0.0;       // Eq. 6.7's smoothing; 0: 1/|V| (the thesis' choice)
  double alpha_n = 1.0;       // Eq. 6.9's smoothing
  double epsilon = 1e-3;      // Eq. 6.14
  double chi2_alpha = 0.05;   // the χ² test's significance level
  double min_expected = 5.0;  // pooling threshold of the χ² test
  std::uint32_t max_models = 8;
  double prior = 0.0;         // P(trav) for PNB; 0: estimated per model (above)
};
inline constexpr std::uint32_t kMaxModels = 32;
// Labelled examples a word needs for its g to count towards Elkan–Noto's c.
inline constexpr std::uint32_t kCSupport = 10;
std::string check_learner(const LearnerConfig& c);  // "" if usable

struct ChiSquare {
  double statistic = 0.0;
  int dof = 0;
  double p_value = 1.0;  // 1 when the histograms cannot be told apart (fewer than two columns, an empty one)
};
// Pearson's test that two histograms over the same words come from one
// distribution (a 2 x K contingency table, sparse words pooled).
ChiSquare chi_square_homogeneity(std::span<const std::uint32_t> a, std::span<const std::uint32_t> b,
                                 double min_expected) noexcept;

enum class Method : std::uint8_t { pnb = 0, pos = 1 };
std::string_view method_name(Method m) noexcept;  // "PNB", "POS"

class TravModels {
 public:
  TravModels(const Vocabulary& vocabulary, const LearnerConfig& config);

  struct Assignment {
    int model = -1;        // -1: not learnt (the local map had no positive word)
    bool created = false;  // a new terrain model
    bool forced = false;   // every model differed, none could be added
    ChiSquare test;        // against the chosen model (created: not tested)
  };
  // Thesis §6.3.4: test, merge (P_m ∪ P_l, U_m ∪ U_l), recompute that model.
  Assignment train(const WordCounts& local_map) noexcept;
  // Replaces everything by these models' counts (a model file's).
  void set_models(std::span<const WordCounts> models);

  const Vocabulary& vocabulary() const noexcept { return vocabulary_; }
  const LearnerConfig& config() const noexcept { return config_; }
  std::uint32_t models() const noexcept { return models_; }
  const WordCounts& counts(std::uint32_t model) const noexcept { return counts_[model]; }
  double pnb_prior(std::uint32_t model) const noexcept { return pnb_prior_[model]; }
  double elkan_noto_c(std::uint32_t model) const noexcept { return c_[model]; }
  double pos_prior() const noexcept { return pos_prior_; }

  // PNB, model m: log P(f|trav) − log P(f|¬trav) (Eq. 6.7–6.10).
  float pnb_log_ratio(std::uint32_t model, std::uint32_t word) const noexcept {
    return pnb_llr_[static_cast<std::size_t>(model) * vocabulary_.size() + word];
  }
  float pnb_prior_logit(std::uint32_t model) const noexcept { return pnb_prior_logit_[model]; }
  // POS: P(trav|f) of model m (Eq. 6.13–6.14), and the featurewise maximum
  // over the models as a logit minus the prior's (Eq. 6.17, 6.15).
  double pos_probability(std::uint32_t model, std::uint32_t word) const noexcept {
    return pos_p_[static_cast<std::size_t>(model) * vocabulary_.size() + word];
  }
  float pos_log_ratio(std::uint32_t word) const noexcept { return pos_llr_[word]; }
  float pos_prior_logit() const noexcept { return pos_prior_logit_; }

  // A cell's P(trav | f_1, ..., f_n) from its words: PNB the maximum over the
  // models of each one's posterior (Eq. 6.12, 6.16), POS the logit update
  // over the featurewise maximum (Eq. 6.15, 6.17). With no word: the prior.
  // 0 with no model.
  double probability(Method method, std::span<const std::uint32_t> words) const noexcept;

 private:
  void refresh(std::uint32_t model) noexcept;
  void refresh_pos() noexcept;

  Vocabulary vocabulary_;
  LearnerConfig config_;
  std::uint32_t models_ = 0;
  std::vector<WordCounts> counts_;         // max_models
  std::vector<float> pnb_llr_;             // max_models x |V|
  std::vector<float> pos_p_;               // max_models x |V|
  std::vector<float> pos_llr_;             // |V|
  std::vector<double> pnb_prior_, c_;      // max_models
  std::vector<float> pnb_prior_logit_;     // max_models
  std::vector<double> labelled_share_;     // max_models: Elkan–Noto's traversable words (labelled + weighted unlabelled)
  double pos_prior_ = 0.5;
  float pos_prior_logit_ = 0.0f;
};

}  // namespace trailnav::perception::trav
