// Image similarities and their pre-processing (thesis §5.1.1 and §5.4).
//
// S (n_Q x n_D): s_ij = cos(f_i^q, f_j^d), Eq. 5.1-5.2, a dot product of unit
// descriptors. Then either
//  - Eq. 5.3, each column (database image) divided by its mean over the
//    queries: an image that resembles every query loses its advantage, and
//  - Eq. 5.4, each row (query) stretched to [0, 1] by its minimum and range;
// or ZCA whitening of S (Eq. 5.11-5.14) followed by Eq. 5.4. The order is
// ours to decide (the thesis does not say): ZCA centres each column, so the
// column means Eq. 5.3 would divide by are zero afterwards; ZCA takes the
// place of Eq. 5.3 (docs/place.md measures both orders).
//
// The descriptors may be kept compactly: each vector as bytes scaled to its
// largest value (a quarter of the floats' memory; docs/place.md measures what
// the rounding costs).
//
// Offline (the whole matrix at once, place-eval); the online filter uses the
// per-row forms in bayes_filter.hpp.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace trailnav::perception::place {

using Matrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Descriptors as bytes: v ≈ code x scale, with the code's own length kept
// for the cosine.
struct CompactDescriptors {
  int length = 0;
  std::vector<std::uint8_t> codes;  // count x length
  std::vector<float> norms;         // |code|, per descriptor (0: no gradients)
  std::size_t count() const noexcept { return norms.size(); }
  void add(std::span<const float> descriptor);
  std::span<const std::uint8_t> code(std::size_t i) const noexcept {
    return {codes.data() + i * static_cast<std::size_t>(length), static_cast<std::size_t>(length)};
  }
};

// A descriptor as bytes into `code` (its size): each value x 255 / the
// largest, rounded. Returns the code's length.
float encode_descriptor(std::span<const float> descriptor, std::span<std::uint8_t> code) noexcept;

// cos of two codes: their dot product over the product of their lengths
// (0 when either has none).
float cosine(std::span<const std::uint8_t> a, float norm_a, std::span<const std::uint8_t> b, float norm_b) noexcept;

// S of unit descriptors (rows of each matrix): queries x database.
Matrix cosine_similarities(const Matrix& queries, const Matrix& database);
Matrix cosine_similarities(const CompactDescriptors& queries, const CompactDescriptors& database);

// Eq. 5.3 in place: every column divided by its mean (a column of zeros stays).
void normalise_columns(Matrix& s);
// Eq. 5.4 in place: every row to [0, 1] (a constant row becomes all ones:
// it says nothing, so every place stays as likely as before).
void stretch_rows(Matrix& s);

// ZCA whitening of S (Eq. 5.11-5.14): columns centred, Σ = E[Ŝᵀ Ŝ] over the
// rows, Ŝ U (Λ + εI)^-1/2 Uᵀ. ε = epsilon_relative x the mean of Σ's
// eigenvalues over the rank min(n_Q, n_D) (so that it scales with the data;
// the thesis says only "small"). Computed through the eigenvectors of the
// smaller of Ŝ Ŝᵀ and Ŝᵀ Ŝ (equal results: Ŝ W = P g(Λ) Pᵀ Ŝ with P the
// eigenvectors of Ŝ Ŝᵀ).
Matrix zca_whiten(const Matrix& s, double epsilon_relative);

// The whitening learnt from `reference` (rows: other queries of the same
// database, e.g. the database against itself) applied to `s`: centred with
// the reference's column means, Σ from the reference's rows. What a robot
// can do before it has driven (it has no queries yet).
Matrix zca_whiten_with(const Matrix& reference, const Matrix& s, double epsilon_relative);

}  // namespace trailnav::perception::place
