// The discrete Bayes filter over database positions (thesis §5.1.2-5.2).
//
// Bel(x_t) = η p(z_t | x_t) Σ_{x_{t-1}} P(x_t | x_{t-1}) Bel(x_{t-1})   (Eq. 5.6)
//
// with the transition of Eq. 5.7 for a step d = x_t - x_{t-1}:
//   c_f for 0 < d < f, c_s for d = 0, c_b for -b < d < 0, 1 elsewhere,
// scaled by α, the sum of a row over x_t (one α for every row: near the
// database's ends the mass a band carries past the end is dropped, not piled
// onto the last images; the update's η restores the sum); and the sensor model of Eq. 5.8, p(z_t | x_t = j)
// ∝ s̃_tj. The thesis' values: f = 5, b = 3, c_f = 500, c_s = 100, c_b = 50.
//
// The prediction is O(n_D), not O(n_D²): every position gets the mass of all
// (the 1 of "elsewhere") plus (c - 1) times the mass of its bands, and a band's
// mass is a difference of two prefix sums of Bel(x') / α.
//
// `reversed` runs the filter on the time-reversed sequences of §5.2: the
// database's order reversed too, so a forward step is d < 0 in the original
// indices. Beliefs stay in the original order either way.
//
// Buffers are sized at construction; predict() and update() allocate nothing.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::perception::place {

struct TransitionModel {
  int f = 5;
  int b = 3;
  double c_f = 500.0;
  double c_s = 100.0;
  double c_b = 50.0;
};

class BayesFilter {
 public:
  // Throws std::invalid_argument for an empty database or a model whose
  // bands or weights are not positive.
  BayesFilter(std::size_t database_size, const TransitionModel& model, bool reversed = false);

  // Bel(x_0) uniform over the database.
  void reset() noexcept;
  // Σ P(x_t | x_{t-1}) Bel(x_{t-1}) into the belief.
  void predict() noexcept;
  // Times the likelihood (n_D values, not negative), normalised. A
  // likelihood of zero everywhere leaves the prediction as it is.
  void update(std::span<const float> likelihood) noexcept;
  // predict() then update(): one query.
  void step(std::span<const float> likelihood) noexcept {
    predict();
    update(likelihood);
  }

  std::span<const double> belief() const noexcept { return belief_; }
  std::size_t size() const noexcept { return belief_.size(); }

 private:
  TransitionModel model_;
  bool reversed_;
  std::vector<double> belief_;
  double inverse_alpha_ = 0.0;  // 1 / α, the same for every source
  std::vector<double> prefix_;         // n_D + 1
};

// B of Eq. 5.9 for a likelihood matrix L (n_Q x n_D, rows ∝ p(z_i | x)):
// the forward pass B_f (queries in order) and the backward pass B_b (both
// sequences reversed), each row of λ √(B_f B_b) normalised to sum 1.
Matrix forward_backward(const Matrix& likelihood, const TransitionModel& model);
// B_f alone (what an online filter has without its lag).
Matrix forward_pass(const Matrix& likelihood, const TransitionModel& model);

}  // namespace trailnav::perception::place
