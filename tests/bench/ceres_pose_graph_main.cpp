// trailnav_ceres_pose_graph: the peer of `trailnav pose-graph optimize`,
// Ceres Solver on the same g2o file (ceres_pose_graph.hpp), in a process of
// its own so that its peak memory is its own. Prints the same JSON fields.
//   trailnav_ceres_pose_graph IN.g2o [--out OUT.g2o] [--max-iterations N] [--tolerance T]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#include "ceres_pose_graph.hpp"

namespace {

std::size_t peak_resident_bytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return static_cast<std::size_t>(std::strtoull(line.c_str() + 6, nullptr, 10)) * 1024u;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace trailnav;
  std::string in, out;
  int max_iterations = 500;
  double tolerance = 1e-6;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--max-iterations" && i + 1 < argc) {
      max_iterations = std::atoi(argv[++i]);
    } else if (a == "--tolerance" && i + 1 < argc) {
      tolerance = std::atof(argv[++i]);
    } else if (a == "-h" || a == "--help") {
      std::puts("trailnav_ceres_pose_graph IN.g2o [--out OUT.g2o] [--max-iterations N] [--tolerance T]: Ceres Solver on a g2o "
                "pose graph, the peer of `trailnav pose-graph optimize` (JSON on stdout)");
      return 0;
    } else if (in.empty() && a[0] != '-') {
      in = a;
    } else {
      std::fprintf(stderr, "trailnav_ceres_pose_graph: unknown argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }
  if (in.empty()) {
    std::fprintf(stderr, "trailnav_ceres_pose_graph: no input file (see --help)\n");
    return 2;
  }
  const auto start = std::chrono::steady_clock::now();
  const slam::G2oCounts c = slam::count_g2o_file(in);
  slam::G2oGraph g;
  const slam::G2oReadResult r = slam::read_g2o_file(in, {std::max<std::size_t>(c.vertices, 1), std::max<std::size_t>(c.edges, 1)}, g);
  if (!c.ok || !r.ok) {
    std::fprintf(stderr, "trailnav_ceres_pose_graph: %s\n", c.ok ? r.error.c_str() : c.error.c_str());
    return 1;
  }
  const bench::CeresOutcome o = bench::solve_with_ceres(g, max_iterations, tolerance);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!out.empty()) {
    std::ofstream f(out, std::ios::binary);
    f << slam::write_g2o(g);
  }
  std::printf("{\"file\": \"%s\", \"method\": \"ceres\", \"vertices\": %zu, \"edges\": %zu, \"initial_chi2\": %.6f, \"chi2\": %.6f, "
              "\"iterations\": %d, \"converged\": %s, \"seconds\": %.3f, \"peak_bytes\": %zu}\n",
              in.c_str(), g.vertex_count(), g.edge_count(), o.initial_chi2, o.chi2, o.iterations, o.converged ? "true" : "false",
              seconds, peak_resident_bytes());
  return 0;
}
