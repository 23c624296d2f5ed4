#include "trailnav/navigation/slam/lm_solver.hpp"

#include <algorithm>
#include <cmath>

namespace trailnav::slam {

template <class Pose>
LmSolver<Pose>::LmSolver(GraphCapacity capacity, Arena& arena, Factorisation kind)
    : capacity_(capacity), cholesky_(arena, kind) {
  const std::size_t d = static_cast<std::size_t>(kDim);
  variable_.reserve(capacity.vertices);
  pair_.reserve(capacity.edges);
  pairs_.reserve(capacity.edges);
  upper_.reserve(capacity.vertices);
  colptr_.reserve(d * capacity.vertices + 1);
  rows_.reserve(d * d * capacity.edges + d * (d + 1) / 2 * capacity.vertices);
  gradient_.reserve(d * capacity.vertices);
  rhs_.reserve(d * capacity.vertices);
  step_.reserve(d * capacity.vertices);
  diagonal_.reserve(d * capacity.vertices);
  backup_.reserve(capacity.vertices);
}

template <class Pose>
bool LmSolver<Pose>::structure(const PoseGraph<Pose>& graph, const std::vector<std::uint8_t>& held, std::string& error) {
  const std::size_t n = graph.vertex_count();
  if (n > capacity_.vertices || graph.edge_count() > capacity_.edges) {
    error = "the graph (" + std::to_string(n) + " vertices, " + std::to_string(graph.edge_count()) +
            " edges) exceeds the solver's capacity (" + std::to_string(capacity_.vertices) + ", " +
            std::to_string(capacity_.edges) + ")";
    return false;
  }
  bool any_constant = false;
  for (std::size_t v = 0; v < n; ++v) any_constant = any_constant || graph.fixed(v) || (!held.empty() && held[v] != 0);
  variable_.assign(n, -1);
  std::int32_t count = 0;
  for (std::size_t v = 0; v < n; ++v) {
    const bool constant = graph.fixed(v) || (!held.empty() && held[v] != 0) || (!any_constant && v == 0);
    if (!constant) variable_[v] = count++;
  }
  pairs_.clear();
  for (const auto& e : graph.edges()) {
    const std::int32_t a = variable_[static_cast<std::size_t>(e.from)], b = variable_[static_cast<std::size_t>(e.to)];
    if (a < 0 || b < 0) continue;
    const auto lo = static_cast<std::uint64_t>(std::min(a, b)), hi = static_cast<std::uint64_t>(std::max(a, b));
    pairs_.push_back(hi << 32 | lo);
  }
  std::sort(pairs_.begin(), pairs_.end());
  pairs_.erase(std::unique(pairs_.begin(), pairs_.end()), pairs_.end());
  upper_.assign(static_cast<std::size_t>(count), 0);
  for (std::uint64_t p : pairs_) ++upper_[static_cast<std::size_t>(p >> 32)];
  pair_.assign(graph.edge_count(), -1);
  for (std::size_t k = 0; k < graph.edge_count(); ++k) {
    const auto& e = graph.edge(k);
    const std::int32_t a = variable_[static_cast<std::size_t>(e.from)], b = variable_[static_cast<std::size_t>(e.to)];
    if (a < 0 || b < 0) continue;
    const auto lo = static_cast<std::uint64_t>(std::min(a, b)), hi = static_cast<std::uint64_t>(std::max(a, b));
    const auto first = std::lower_bound(pairs_.begin(), pairs_.end(), hi << 32);
    const auto it = std::lower_bound(first, pairs_.end(), hi << 32 | lo);
    pair_[k] = static_cast<std::int32_t>(it - first);
  }
  const int d = kDim;
  colptr_.assign(static_cast<std::size_t>(count * d) + 1, 0);
  rows_.clear();
  std::size_t p = 0;
  for (int c = 0; c < count; ++c) {
    const std::size_t up = static_cast<std::size_t>(upper_[static_cast<std::size_t>(c)]);
    for (int k = 0; k < d; ++k) {
      for (std::size_t q = 0; q < up; ++q) {
        const int r = static_cast<int>(pairs_[p + q] & 0xffffffffu);
        for (int i = 0; i < d; ++i) rows_.push_back(r * d + i);
      }
      for (int i = 0; i <= k; ++i) rows_.push_back(c * d + i);
      colptr_[static_cast<std::size_t>(c * d + k + 1)] = static_cast<int>(rows_.size());
    }
    p += up;
  }
  const auto dims = static_cast<std::size_t>(count * d);
  gradient_.assign(dims, 0.0);
  rhs_.assign(dims, 0.0);
  step_.assign(dims, 0.0);
  diagonal_.assign(dims, 0.0);
  if (count == 0) return true;
  return cholesky_.analyse(count * d, colptr_, rows_, error);
}

template <class Pose>
double LmSolver<Pose>::assemble(const PoseGraph<Pose>& graph) {
  constexpr int d = kDim;
  using Matrix = typename Pose::Matrix;
  using Vector = typename Pose::Vector;
  std::span<double> h = cholesky_.values();
  std::fill(h.begin(), h.end(), 0.0);
  std::fill(gradient_.begin(), gradient_.end(), 0.0);
  auto add_diagonal = [&](std::int32_t v, const Matrix& m) {
    const int base = d * upper_[static_cast<std::size_t>(v)];
    for (int k = 0; k < d; ++k) {
      double* col = h.data() + colptr_[static_cast<std::size_t>(v * d + k)] + base;
      for (int r = 0; r <= k; ++r) col[r] += m(r, k);
    }
  };
  auto add_off = [&](std::int32_t column, std::int32_t local, const Matrix& m) {  // m: rows of the lower var, columns of `column`
    for (int k = 0; k < d; ++k) {
      double* col = h.data() + colptr_[static_cast<std::size_t>(column * d + k)] + d * local;
      for (int r = 0; r < d; ++r) col[r] += m(r, k);
    }
  };
  EdgeLinearisation<Pose> lin;
  double chi2 = 0.0;
  for (std::size_t k = 0; k < graph.edge_count(); ++k) {
    const auto& e = graph.edge(k);
    const std::int32_t a = variable_[static_cast<std::size_t>(e.from)], b = variable_[static_cast<std::size_t>(e.to)];
    linearise(e.measurement, graph.pose(static_cast<std::size_t>(e.from)), graph.pose(static_cast<std::size_t>(e.to)), lin);
    const Vector we = e.information * lin.error;
    chi2 += lin.error.dot(we);
    Matrix jiw, jjw;
    if (a >= 0) {
      jiw = lin.ji.transpose() * e.information;
      add_diagonal(a, jiw * lin.ji);
      Eigen::Map<Vector>(gradient_.data() + a * d) += lin.ji.transpose() * we;
    }
    if (b >= 0) {
      jjw = lin.jj.transpose() * e.information;
      add_diagonal(b, jjw * lin.jj);
      Eigen::Map<Vector>(gradient_.data() + b * d) += lin.jj.transpose() * we;
    }
    if (a >= 0 && b >= 0) {
      if (a < b) {
        add_off(b, pair_[k], jiw * lin.jj);
      } else {
        add_off(a, pair_[k], jjw * lin.ji);
      }
    }
  }
  return chi2;
}

template <class Pose>
LmReport LmSolver<Pose>::solve(PoseGraph<Pose>& graph, const LmOptions& options, const std::vector<std::uint8_t>& held) {
  LmReport report;
  constexpr int d = kDim;
  if (!structure(graph, held, report.error)) return report;
  const std::size_t dims = gradient_.size();
  report.variables = static_cast<int>(dims);
  double chi2 = assemble(graph);
  report.initial_chi2 = chi2;
  report.chi2 = chi2;
  if (dims == 0) {
    report.ok = true;
    report.converged = true;
    return report;
  }
  std::span<double> h = cholesky_.values();
  auto diagonal_index = [&](std::size_t i) {
    const std::size_t v = i / static_cast<std::size_t>(d), k = i % static_cast<std::size_t>(d);
    return static_cast<std::size_t>(colptr_[i]) + static_cast<std::size_t>(d * upper_[v]) + k;
  };
  auto save_diagonal = [&] {
    for (std::size_t i = 0; i < dims; ++i) diagonal_[i] = h[diagonal_index(i)];
  };
  save_diagonal();
  auto damping = [&](std::size_t i) { return std::clamp(diagonal_[i], 1e-6, 1e32); };
  double lambda = 1e-4;
  double nu = 2.0;
  backup_.resize(graph.vertex_count());
  while (report.iterations < options.max_iterations) {
    if (options.progress && report.iterations > 0) options.progress(report.iterations, chi2);
    ++report.iterations;
    for (std::size_t i = 0; i < dims; ++i) h[diagonal_index(i)] = diagonal_[i] + lambda * damping(i);
    std::string error;
    if (!cholesky_.factorise(error)) {
      if (error != "not positive definite") {
        report.error = error;
        return report;
      }
      lambda *= nu;
      nu *= 2.0;
      if (lambda > 1e30) break;
      continue;
    }
    for (std::size_t i = 0; i < dims; ++i) rhs_[i] = -gradient_[i];
    if (!cholesky_.solve(rhs_, step_, report.error)) return report;
    std::copy(graph.poses().begin(), graph.poses().end(), backup_.begin());
    for (std::size_t v = 0; v < graph.vertex_count(); ++v) {
      const std::int32_t i = variable_[v];
      if (i < 0) continue;
      graph.pose(v) = graph.pose(v).plus(Eigen::Map<const typename Pose::Vector>(step_.data() + i * d));
    }
    const double new_chi2 = graph.chi2();
    double predicted = 0.0;
    for (std::size_t i = 0; i < dims; ++i) predicted += step_[i] * (lambda * damping(i) * step_[i] - gradient_[i]);
    const double rho = (chi2 - new_chi2) / predicted;
    // A step is taken only when χ² really fell and the linear model predicted
    // a fall: on an ill-conditioned system (an information entry of 1e61 the
    // fuzzer wrote) the solve can return a step whose predicted change is
    // negative, and a rise divided by it looked like a gain (χ² 101 -> 1,449).
    if (std::isfinite(new_chi2) && new_chi2 < chi2 && predicted > 0.0 && rho > 0.0 && std::isfinite(rho)) {
      ++report.steps_taken;
      const double decrease = (chi2 - new_chi2) / std::max(chi2, 1e-300);
      const double t = 2.0 * rho - 1.0;
      lambda *= std::max(1.0 / 3.0, 1.0 - t * t * t);
      nu = 2.0;
      chi2 = assemble(graph);
      save_diagonal();
      if (decrease < options.relative_tolerance) {
        report.converged = true;
        break;
      }
    } else {
      std::copy(backup_.begin(), backup_.end(), graph.poses().begin());
      lambda *= nu;
      nu *= 2.0;
      if (lambda > 1e30) {
        report.converged = true;  // no step lowers χ² any more
        break;
      }
    }
  }
  report.chi2 = chi2;
  report.factor_nonzeros = cholesky_.factor_nonzeros();
  report.ok = true;
  return report;
}

template class LmSolver<Se2>;
template class LmSolver<Se3>;

}  // namespace trailnav::slam
