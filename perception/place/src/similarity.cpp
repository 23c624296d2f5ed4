#include "trailnav/perception/place/similarity.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

namespace trailnav::perception::place {

float encode_descriptor(std::span<const float> descriptor, std::span<std::uint8_t> code) noexcept {
  float largest = 0.0f;
  for (float v : descriptor) largest = std::max(largest, v);
  const float scale = largest > 0.0f ? 255.0f / largest : 0.0f;
  double norm = 0.0;
  for (std::size_t k = 0; k < descriptor.size(); ++k) {
    const auto c = static_cast<std::uint8_t>(std::lround(std::max(descriptor[k], 0.0f) * scale));
    code[k] = c;
    norm += static_cast<double>(c) * static_cast<double>(c);
  }
  return static_cast<float>(std::sqrt(norm));
}

void CompactDescriptors::add(std::span<const float> descriptor) {
  if (length == 0) length = static_cast<int>(descriptor.size());
  const std::size_t at = codes.size();
  codes.resize(at + descriptor.size());
  norms.push_back(encode_descriptor(descriptor, {codes.data() + at, descriptor.size()}));
}

float cosine(std::span<const std::uint8_t> a, float norm_a, std::span<const std::uint8_t> b, float norm_b) noexcept {
  if (norm_a == 0.0f || norm_b == 0.0f) return 0.0f;
  // Products of bytes fit 17 bits: a 32-bit sum holds 32,768 of them, so
  // sum in blocks.
  std::uint64_t total = 0;
  const std::size_t n = a.size();
  for (std::size_t start = 0; start < n; start += 32768) {
    const std::size_t end = std::min(n, start + 32768);
    std::uint32_t sum = 0;
    for (std::size_t k = start; k < end; ++k) sum += static_cast<std::uint32_t>(a[k]) * b[k];
    total += sum;
  }
  return static_cast<float>(static_cast<double>(total) / (static_cast<double>(norm_a) * static_cast<double>(norm_b)));
}

Matrix cosine_similarities(const Matrix& queries, const Matrix& database) {
  Matrix s = queries * database.transpose();
  return s;
}

Matrix cosine_similarities(const CompactDescriptors& queries, const CompactDescriptors& database) {
  Matrix s(static_cast<Eigen::Index>(queries.count()), static_cast<Eigen::Index>(database.count()));
  for (std::size_t i = 0; i < queries.count(); ++i)
    for (std::size_t j = 0; j < database.count(); ++j)
      s(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
          cosine(queries.code(i), queries.norms[i], database.code(j), database.norms[j]);
  return s;
}

void normalise_columns(Matrix& s) {
  const Eigen::RowVectorXf mean = s.colwise().mean();
  for (Eigen::Index j = 0; j < s.cols(); ++j)
    if (mean(j) != 0.0f) s.col(j) /= mean(j);
}

void stretch_rows(Matrix& s) {
  for (Eigen::Index i = 0; i < s.rows(); ++i) {
    auto row = s.row(i);
    const float lo = row.minCoeff();
    const float range = row.maxCoeff() - lo;
    if (range > 0.0f) {
      row = (row.array() - lo) / range;
    } else {
      row.setOnes();
    }
  }
}

Matrix zca_whiten(const Matrix& s, double epsilon_relative) {
  using MatrixD = Eigen::MatrixXd;
  const Eigen::Index n_q = s.rows();
  if (n_q > s.cols()) return zca_whiten_with(s, s, epsilon_relative);  // Σ is the smaller: Eq. 5.12-5.14 as written
  MatrixD centred = s.cast<double>();
  centred.rowwise() -= centred.colwise().mean();  // Eq. 5.11
  const double rows = static_cast<double>(std::max<Eigen::Index>(n_q, 1));
  // Ŝ Ŝᵀ = P M Pᵀ; Σ's non-zero eigenvalues are M / n_Q.
  const MatrixD gram = centred * centred.transpose();
  Eigen::SelfAdjointEigenSolver<MatrixD> eig(gram);
  const Eigen::VectorXd lambda = (eig.eigenvalues().array().max(0.0) / rows).matrix();
  const double epsilon = epsilon_relative * lambda.sum() / static_cast<double>(n_q);
  const Eigen::VectorXd g = (lambda.array() + epsilon).rsqrt().matrix();
  const MatrixD& p = eig.eigenvectors();
  return (p * (g.asDiagonal() * (p.transpose() * centred))).cast<float>();
}

Matrix zca_whiten_with(const Matrix& reference, const Matrix& s, double epsilon_relative) {
  using MatrixD = Eigen::MatrixXd;
  const Eigen::Index n_r = reference.rows();
  const Eigen::Index n_d = reference.cols();
  MatrixD centred = reference.cast<double>();
  const Eigen::RowVectorXd mean = centred.colwise().mean();
  centred.rowwise() -= mean;
  const double rows = static_cast<double>(std::max<Eigen::Index>(n_r, 1));
  const MatrixD sigma = centred.transpose() * centred / rows;
  Eigen::SelfAdjointEigenSolver<MatrixD> eig(sigma);
  const Eigen::VectorXd lambda = eig.eigenvalues().array().max(0.0).matrix();
  const double epsilon = epsilon_relative * lambda.sum() / static_cast<double>(std::min(n_r, n_d));
  const Eigen::VectorXd g = (lambda.array() + epsilon).rsqrt().matrix();
  const MatrixD& u = eig.eigenvectors();
  MatrixD q = s.cast<double>();
  q.rowwise() -= mean;
  return (q * (u * g.asDiagonal() * u.transpose())).cast<float>();
}

}  // namespace trailnav::perception::place
