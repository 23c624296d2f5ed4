// Fuzzes the pose-graph library from g2o text: any bytes give a graph or a
// message naming a line, never a crash; a graph that loads writes back text
// that reads to the same text, and both solvers (the exact one and SMF with
// parts of 8, so that small graphs have levels) finish on it with a report
// or an error, their χ² finite when the input's was, never above it.
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "check.hpp"

#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/g2o_io.hpp"
#include "trailnav/navigation/slam/lm_solver.hpp"
#include "trailnav/navigation/slam/smf.hpp"

using namespace trailnav::slam;

namespace {

constexpr GraphCapacity kCapacity{64, 256};

template <class Pose>
void solve_both(const PoseGraph<Pose>& graph) {
  const double before = graph.chi2();
  LmOptions lm;
  lm.max_iterations = 20;
  {
    PoseGraph<Pose> g = graph;
    Arena arena(8u << 20);
    LmSolver<Pose> solver(kCapacity, arena);
    const LmReport r = solver.solve(g, lm);
    check(r.ok != !r.error.empty() || r.ok);
    if (r.ok && std::isfinite(before)) {
      check(std::isfinite(r.chi2));
      check(r.chi2 <= before * (1.0 + 1e-9) + 1e-9);
    }
  }
  {
    PoseGraph<Pose> g = graph;
    Arena arena(8u << 20);
    SmfOptions o;
    o.max_part = 8;
    o.lm = lm;
    SmfSolver<Pose> solver(kCapacity, o, arena);
    const SmfReport r = solver.solve(g);
    check(r.ok || !r.error.empty());
    if (r.ok) check(std::isfinite(r.chi2) || !std::isfinite(before));
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  G2oGraph g;
  const G2oReadResult r = read_g2o(text, "fuzz.g2o", kCapacity, g);
  check(r.ok == r.error.empty());
  if (!r.ok) {
    check(r.error.rfind("fuzz.g2o", 0) == 0);
    return 0;
  }
  const std::string written = write_g2o(g);
  G2oGraph back;
  const G2oReadResult again = read_g2o(written, "written.g2o", kCapacity, back);
  check(again.ok);
  check(write_g2o(back) == written);
  if (g.kind == GraphKind::spatial) {
    solve_both(g.spatial);
  } else {
    solve_both(g.planar);
  }
  return 0;
}
