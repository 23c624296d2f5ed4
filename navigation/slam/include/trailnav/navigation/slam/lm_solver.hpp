// The exact solver: Levenberg–Marquardt on Eq. 2.3 (min Σ e_ijᵀ Ω_ij e_ij),
// each step solving (H + λD) δ = −g with H = Σ Jᵀ Ω J, g = Σ Jᵀ Ω e and D
// H's diagonal (clamped to 1e-6..1e32: Marquardt's scaling, so that metres
// and radians are damped alike), assembled block by block into the upper
// triangle of a sparse matrix and factorised by SparseCholesky. λ starts at
// 1e-4 and follows the gain ratio ρ (actual over predicted decrease): a step
// with ρ > 0 is taken and λ ×= max(1/3, 1 − (2ρ − 1)³); otherwise it is undone
// and λ grows by ν, ν doubling (Nielsen's rule). With λI instead (g2o's
// damping, first tried) ETHCampus took 222 iterations from its guess; with
// the scaling 75, as many as Ceres Solver takes.
//
// The gauge: fixed vertices (FIX) are constants; a graph with none has its
// first vertex held, which changes the poses by one rigid motion and χ² not
// at all.
//
// Stopping: when a taken step lowers χ² by less than `relative_tolerance` of
// it (Ceres' function tolerance, so that the side-by-side stops alike), after
// `max_iterations` steps, or when λ has grown past 1e30 (no step lowers χ²:
// a minimum within the float precision).
//
// Memory: every array is reserved for the capacity given at construction
// (vertices, edges); the factorisation lives in the Arena. Solving any graph
// within the capacity allocates nothing more on the heap.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "trailnav/navigation/slam/pose_graph.hpp"
#include "trailnav/navigation/slam/sparse_cholesky.hpp"

namespace trailnav::slam {

struct LmOptions {
  int max_iterations = 500;  // MIT from its guess takes about 380
  double relative_tolerance = 1e-6;
  // After each iteration (its number, χ² then): a progress bar's hook.
  std::function<void(int iteration, double chi2)> progress;
};

struct LmReport {
  bool ok = false;
  std::string error;
  double initial_chi2 = 0.0;
  double chi2 = 0.0;
  int iterations = 0;        // steps tried (taken or not)
  int steps_taken = 0;
  bool converged = false;    // stopped by the tolerance (not the iteration limit)
  int variables = 0;         // rows of H
  double factor_nonzeros = 0.0;
};

template <class Pose>
class LmSolver {
 public:
  static constexpr int kDim = Pose::kDim;
  LmSolver(GraphCapacity capacity, Arena& arena, Factorisation kind = Factorisation::automatic);

  // Optimises `graph`'s poses in place. `held` (may be empty) marks vertices
  // held constant beside the graph's own fixed ones (the refinement of a part
  // holds its separators).
  LmReport solve(PoseGraph<Pose>& graph, const LmOptions& options, const std::vector<std::uint8_t>& held = {});

 private:
  bool structure(const PoseGraph<Pose>& graph, const std::vector<std::uint8_t>& held, std::string& error);
  double assemble(const PoseGraph<Pose>& graph);  // H, g, returns χ²

  GraphCapacity capacity_;
  SparseCholesky cholesky_;
  std::vector<std::int32_t> variable_;   // per vertex: its variable index, −1 when constant
  std::vector<std::int32_t> pair_;       // per edge: index of its off-diagonal block in the column's list, −1 none
  std::vector<std::uint64_t> pairs_;     // scratch: (column var << 32 | row var) of off-diagonal blocks
  std::vector<int> colptr_, rows_;
  std::vector<int> upper_;               // per variable: off-diagonal blocks above its diagonal block
  std::vector<double> gradient_, rhs_, step_;
  std::vector<Pose> backup_;
  std::vector<double> diagonal_;         // H's diagonal before damping
};

}  // namespace trailnav::slam
