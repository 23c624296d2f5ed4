// A sparse Cholesky factorisation (SuiteSparse's CHOLMOD, supernodal where
// it pays) whose every byte comes from an Arena: CHOLMOD's allocation hooks
// point into the arena while this object calls it, so what a solve needs is
// bounded by the arena the configuration sized, and a pattern too large for
// it is an error, not a swap storm. The pattern (upper triangle, compressed
// columns) is analysed once — fill-reducing ordering and symbolic factor —
// and then factorised and solved for new values as often as needed.
#pragma once

#include "trailnav/navigation/slam/arena.hpp"

#include <cstddef>
#include <span>
#include <string>

namespace trailnav::slam {


// Supernodal factors pay on large graphs but run CHOLMOD's OpenMP regions
// (threads, and libgomp's own malloc); simplicial ones stay on the calling
// thread and in the arena: what SMF's parts (at most max_part poses) use.
enum class Factorisation { automatic, simplicial };

class SparseCholesky {
 public:
  // `arena` outlives this object; every CHOLMOD allocation is made in it.
  explicit SparseCholesky(Arena& arena, Factorisation kind = Factorisation::automatic);
  ~SparseCholesky();
  SparseCholesky(const SparseCholesky&) = delete;
  SparseCholesky& operator=(const SparseCholesky&) = delete;

  // The n×n pattern's upper triangle: column c's rows are rows[colptr[c] ..
  // colptr[c+1]), ascending, each ≤ c. Replaces any earlier pattern.
  bool analyse(int n, std::span<const int> colptr, std::span<const int> rows, std::string& error);
  // The values of the analysed pattern, written in place before factorise().
  std::span<double> values() noexcept;
  // False with error "not positive definite" when it is not (the caller
  // damps more and tries again), or when the arena is exhausted.
  bool factorise(std::string& error);
  // x = A⁻¹ b for the last factorisation.
  bool solve(std::span<const double> b, std::span<double> x, std::string& error);

  int size() const noexcept { return n_; }
  bool supernodal() const noexcept;
  double factor_nonzeros() const noexcept;  // entries of L

 private:
  struct Impl;
  Impl* impl_ = nullptr;
  int n_ = 0;
};

}  // namespace trailnav::slam
