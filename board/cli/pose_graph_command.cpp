// `trailnav pose-graph`: pose-graph SLAM back end offline (thesis chapter 3):
// optimise a g2o file exactly or with the memory-bounded hierarchical method
// (SMF), compare two solutions edge by edge (Table 3.2), and generate the
// synthetic Manhattan worlds of the thesis' memory experiment.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>

#include "commands.hpp"
#include "terminal.hpp"
#include "trailnav/navigation/slam/arena.hpp"
#include "trailnav/navigation/slam/compare.hpp"
#include "trailnav/navigation/slam/g2o_io.hpp"
#include "trailnav/navigation/slam/lm_solver.hpp"
#include "trailnav/navigation/slam/manhattan.hpp"
#include "trailnav/navigation/slam/smf.hpp"

namespace trailnav::cli {
namespace {

using namespace trailnav::slam;

// The process' peak resident memory (VmHWM), bytes; 0 when unknown.
std::size_t peak_resident_bytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return static_cast<std::size_t>(std::strtoull(line.c_str() + 6, nullptr, 10)) * 1024u;
  }
  return 0;
}

bool write_text(const std::string& path, const std::string& text, const char* who) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  f.close();
  if (!f) {
    std::fprintf(stderr, "%s: cannot write %s\n", who, path.c_str());
    return false;
  }
  return true;
}

struct OptimizeOptions {
  std::string in, out, method = "smf", report = "text";
  int max_part = 500;
  int max_iterations = 500;
  double tolerance = 1e-6;
  double memory_mb = 0.0;
  bool quiet = false;
};

struct Solved {
  bool ok = false;
  std::string error;
  double initial_chi2 = 0.0, chi2 = 0.0;
  int iterations = 0, levels = 1, part_solves = 0;
  std::size_t top_vertices = 0;
  std::size_t solver_bytes = 0, arena_bytes = 0;
  double factor_nonzeros = 0.0;  // exact: entries of the Cholesky factor L
  std::size_t hierarchy_bytes = 0, hierarchy_arena_bytes = 0;  // SMF's levels (high-water, arena)
};

template <class Pose>
Solved solve(PoseGraph<Pose>& graph, GraphCapacity capacity, const OptimizeOptions& o) {
  Solved s;
  const bool smf = o.method == "smf";
  // The arena: for SMF one part's factor (at worst dense: its lower
  // triangle, twice for CHOLMOD's workspace) and 16 MiB; for the exact
  // solver what --memory-mb says (2 GiB by default: untouched pages cost
  // nothing, and a cap on the process is what bounds it).
  const double bytes = o.memory_mb > 0.0 ? o.memory_mb * 1048576.0
                       : smf         ? static_cast<double>(smf_part_arena_bytes(Pose::kDim, o.max_part))
                                     : 2048.0 * 1048576.0;
  s.arena_bytes = static_cast<std::size_t>(bytes);
  Arena arena(s.arena_bytes);
  ProgressBar bar(smf ? "SMF" : "Levenberg-Marquardt", 100.0, "%");
  LmOptions lm;
  lm.max_iterations = o.max_iterations;
  lm.relative_tolerance = o.tolerance;
  if (smf) {
    SmfOptions so;
    so.max_part = o.max_part;
    so.lm = lm;
    if (!o.quiet) so.progress = [&](double f) { bar.update(100.0 * f); };
    SmfSolver<Pose> solver(capacity, so, arena);
    const SmfReport r = solver.solve(graph);
    if (!o.quiet) bar.finish();
    s.ok = r.ok;
    s.error = r.error;
    s.initial_chi2 = r.initial_chi2;
    s.chi2 = r.chi2;
    s.iterations = r.iterations;
    s.levels = r.levels;
    s.part_solves = r.part_solves;
    s.hierarchy_bytes = solver.hierarchy_arena().high_water();
    s.hierarchy_arena_bytes = solver.hierarchy_arena().capacity();
    s.top_vertices = r.levels == 0 ? 0 : r.level[static_cast<std::size_t>(r.levels) - 1].vertices;
  } else {
    if (!o.quiet) lm.progress = [&](int it, double) { bar.update(100.0 * it / o.max_iterations); };
    LmSolver<Pose> solver(capacity, arena);
    const LmReport r = solver.solve(graph, lm);
    if (!o.quiet) bar.finish();
    s.ok = r.ok;
    s.error = r.error;
    s.initial_chi2 = r.initial_chi2;
    s.chi2 = r.chi2;
    s.iterations = r.iterations;
    s.top_vertices = graph.vertex_count();
    s.factor_nonzeros = r.factor_nonzeros;
  }
  s.solver_bytes = arena.high_water();
  return s;
}

int optimize(const OptimizeOptions& o) {
  const char* who = "trailnav pose-graph optimize";
  if (o.method != "smf" && o.method != "exact") {
    std::fprintf(stderr, "%s: --method is smf or exact, not '%s'\n", who, o.method.c_str());
    return 2;
  }
  if (o.report != "text" && o.report != "json") {
    std::fprintf(stderr, "%s: --report is text or json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  if (o.max_part < 10 || o.max_part > 100000) {
    std::fprintf(stderr, "%s: --max-part %d is outside 10..100000\n", who, o.max_part);
    return 2;
  }
  const auto start = std::chrono::steady_clock::now();
  const G2oCounts counts = count_g2o_file(o.in);
  if (!counts.ok) {
    std::fprintf(stderr, "%s: %s\n", who, counts.error.c_str());
    return 1;
  }
  const GraphCapacity capacity{std::max<std::size_t>(counts.vertices, 1), std::max<std::size_t>(counts.edges, 1)};
  G2oGraph g;
  const G2oReadResult read = read_g2o_file(o.in, capacity, g);
  if (!read.ok) {
    std::fprintf(stderr, "%s: %s\n", who, read.error.c_str());
    return 1;
  }
  const Solved s = g.kind == GraphKind::spatial ? solve(g.spatial, capacity, o) : solve(g.planar, capacity, o);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!s.ok) {
    std::fprintf(stderr, "%s: %s: %s\n", who, o.in.c_str(), s.error.c_str());
    return 1;
  }
  if (!o.out.empty() && !write_text(o.out, write_g2o(g), who)) return 1;
  const std::size_t peak = peak_resident_bytes();
  if (o.report == "json") {
    std::printf(
        "{\"file\": \"%s\", \"method\": \"%s\", \"kind\": \"%s\", \"vertices\": %zu, \"edges\": %zu, \"initial_chi2\": %.6f, "
        "\"chi2\": %.6f, \"iterations\": %d, \"levels\": %d, \"part_solves\": %d, \"max_part\": %d, \"seconds\": %.3f, "
        "\"peak_bytes\": %zu, \"solver_bytes\": %zu, \"hierarchy_bytes\": %zu, \"factor_nonzeros\": %.0f}\n",
        o.in.c_str(), o.method.c_str(), g.kind == GraphKind::spatial ? "SE3" : "SE2", g.vertex_count(), g.edge_count(),
        s.initial_chi2, s.chi2, s.iterations, s.levels, s.part_solves, o.max_part, seconds, peak, s.solver_bytes,
        s.hierarchy_bytes, s.factor_nonzeros);
  } else {
    std::printf("%s: %s graph, %zu vertices, %zu edges\n", o.in.c_str(), graph_kind_name(g.kind), g.vertex_count(), g.edge_count());
    std::printf("method %s: chi2 %.4f -> %.4f, %d iterations", o.method.c_str(), s.initial_chi2, s.chi2, s.iterations);
    if (o.method == "smf") std::printf(", %d levels (top %zu vertices), %d part solves of at most %d vertices", s.levels, s.top_vertices, s.part_solves, o.max_part);
    std::printf("\ntime %.3f s (reading included); peak resident memory %.1f MiB, of it the solver's factorisations %.1f MiB (of an arena of %.0f MiB)\n",
                seconds, static_cast<double>(peak) / 1048576.0, static_cast<double>(s.solver_bytes) / 1048576.0,
                static_cast<double>(s.arena_bytes) / 1048576.0);
    if (o.method == "smf") {
      std::printf("the hierarchy's levels %.1f MiB (of an arena of %.0f MiB sized for the capacity)\n",
                  static_cast<double>(s.hierarchy_bytes) / 1048576.0, static_cast<double>(s.hierarchy_arena_bytes) / 1048576.0);
    }
    if (!o.out.empty()) std::printf("written to %s\n", o.out.c_str());
  }
  return 0;
}

struct CompareOptions {
  std::string a, b, report = "text";
};

int compare(const CompareOptions& o) {
  const char* who = "trailnav pose-graph compare";
  if (o.report != "text" && o.report != "json") {
    std::fprintf(stderr, "%s: --report is text or json, not '%s'\n", who, o.report.c_str());
    return 2;
  }
  G2oGraph a, b;
  for (auto [path, graph] : {std::pair{&o.a, &a}, std::pair{&o.b, &b}}) {
    const G2oCounts c = count_g2o_file(*path);
    if (!c.ok) {
      std::fprintf(stderr, "%s: %s\n", who, c.error.c_str());
      return 1;
    }
    const G2oReadResult r = read_g2o_file(*path, {std::max<std::size_t>(c.vertices, 1), std::max<std::size_t>(c.edges, 1)}, *graph);
    if (!r.ok) {
      std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
      return 1;
    }
  }
  if (a.kind != b.kind) {
    std::fprintf(stderr, "%s: %s is %s, %s is %s\n", who, o.a.c_str(), graph_kind_name(a.kind), o.b.c_str(), graph_kind_name(b.kind));
    return 1;
  }
  const EdgeErrorStats s = a.kind == GraphKind::spatial ? compare_graphs(a.spatial, b.spatial) : compare_graphs(a.planar, b.planar);
  if (!s.ok) {
    std::fprintf(stderr, "%s: %s\n", who, s.error.c_str());
    return 1;
  }
  constexpr double kDeg = 180.0 / M_PI;
  if (o.report == "json") {
    std::printf("{\"a\": \"%s\", \"b\": \"%s\", \"edges\": %zu, \"mean\": %.6f, \"std\": %.6f, \"max\": %.6f, "
                "\"rotation_mean_deg\": %.6f, \"rotation_max_deg\": %.6f, \"chi2_a\": %.6f, \"chi2_b\": %.6f}\n",
                o.a.c_str(), o.b.c_str(), s.edges, s.mean, s.std, s.max, s.rotation_mean * kDeg, s.rotation_max * kDeg, a.chi2(),
                b.chi2());
  } else {
    std::printf("per-edge error of %s against %s over its %zu edges (thesis Table 3.2):\n", o.a.c_str(), o.b.c_str(), s.edges);
    std::printf("  translation mean %.4f m, std %.4f m, max %.4f m; rotation mean %.4f deg, max %.4f deg\n", s.mean, s.std,
                s.max, s.rotation_mean * kDeg, s.rotation_max * kDeg);
    std::printf("  chi2: %.4f against %.4f\n", a.chi2(), b.chi2());
  }
  return 0;
}

struct GenerateOptions {
  std::string world = "manhattan", out, truth_out;
  ManhattanOptions manhattan;
};

int generate(const GenerateOptions& o) {
  const char* who = "trailnav pose-graph generate";
  if (o.world != "manhattan") {
    std::fprintf(stderr, "%s: --world is manhattan, not '%s'\n", who, o.world.c_str());
    return 2;
  }
  if (o.manhattan.nodes < 2 || o.manhattan.nodes > 50'000'000) {
    std::fprintf(stderr, "%s: --nodes %zu is outside 2..50000000\n", who, o.manhattan.nodes);
    return 2;
  }
  const GraphCapacity capacity{o.manhattan.nodes, o.manhattan.nodes * (1 + static_cast<std::size_t>(o.manhattan.closures_per_pose))};
  PoseGraph2d g(capacity);
  std::unique_ptr<PoseGraph2d> truth;
  if (!o.truth_out.empty()) truth = std::make_unique<PoseGraph2d>(capacity);
  const ManhattanResult r = generate_manhattan(o.manhattan, g, truth.get());
  if (!r.ok) {
    std::fprintf(stderr, "%s: %s\n", who, r.error.c_str());
    return 2;
  }
  if (!write_text(o.out, write_g2o(g), who)) return 1;
  if (truth && !write_text(o.truth_out, write_g2o(*truth), who)) return 1;
  std::printf("%s: Manhattan world, seed %llu: %zu poses, %zu edges (%zu loop closures, %.2f edges a pose); chi2 of the guess %.1f\n",
              o.out.c_str(), static_cast<unsigned long long>(o.manhattan.seed), g.vertex_count(), g.edge_count(), r.closures,
              static_cast<double>(g.edge_count()) / static_cast<double>(g.vertex_count()), g.chi2());
  return 0;
}

}  // namespace

void add_pose_graph_command(CLI::App& app) {
  auto* pg = app.add_subcommand(
      "pose-graph",
      "Pose-graph SLAM back end (thesis chapter 3), offline: `optimize` a g2o file exactly (Levenberg-\n"
      "Marquardt on a sparse Cholesky) or with the memory-bounded hierarchical method (SMF: parts of at\n"
      "most --max-part vertices, none solved larger), `compare` two solutions edge by edge, `generate`\n"
      "synthetic Manhattan worlds. docs/slam.md.\n"
      "Examples:\n"
      "  trailnav pose-graph optimize ../shared/data/g2o/se-sync_m3500.g2o --method smf --out m3500-smf.g2o\n"
      "  trailnav pose-graph optimize ../shared/data/g2o/se-sync_m3500.g2o --method exact --out m3500-exact.g2o\n"
      "  trailnav pose-graph compare m3500-smf.g2o m3500-exact.g2o\n"
      "  trailnav pose-graph generate --world manhattan --nodes 200000 --seed 1 --out m200k.g2o");
  pg->require_subcommand(1);

  static OptimizeOptions opt;
  auto* o = pg->add_subcommand(
      "optimize",
      "Optimise a g2o pose graph (VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT, FIX). Vertices the\n"
      "file fixes stay; a graph with none keeps its first vertex. Prints chi2 before and after, iterations,\n"
      "levels, time and peak memory (--report json: one object with vertices, edges, chi2, iterations,\n"
      "levels, seconds, peak_bytes, ...). Exit 1 for a malformed file (its line named) or a failed solve.");
  o->add_option("input", opt.in, "g2o file")->required();
  o->add_option("--method", opt.method, "smf (hierarchical, bounded memory) or exact")->capture_default_str();
  o->add_option("--max-part", opt.max_part, "SMF: most vertices in a part (the thesis: 500)")->capture_default_str();
  o->add_option("--out", opt.out, "Write the optimised graph here (g2o)");
  o->add_option("--report", opt.report, "text or json (on stdout)")->capture_default_str();
  o->add_option("--max-iterations", opt.max_iterations, "Levenberg-Marquardt steps per solve at most")->capture_default_str();
  o->add_option("--tolerance", opt.tolerance, "Stop when a step lowers chi2 by less than this share of it")->capture_default_str();
  o->add_option("--memory-mb", opt.memory_mb,
                "The solver's arena for factorisations (default: SMF one part's worst case + 16 MiB; exact 2048)");
  o->add_flag("--quiet", opt.quiet, "No progress bar");
  o->callback([] { std::exit(optimize(opt)); });

  static CompareOptions cmp;
  auto* c = pg->add_subcommand("compare",
                               "Per-edge error of A against B (same vertex ids): for each edge of A, the relative pose in A\n"
                               "against the same in B; mean, standard deviation and maximum of its translation (thesis\n"
                               "Table 3.2), and of its rotation. Gauge-free.");
  c->add_option("a", cmp.a, "g2o file (e.g. SMF's solution)")->required();
  c->add_option("b", cmp.b, "g2o file (e.g. the exact solution)")->required();
  c->add_option("--report", cmp.report, "text or json (on stdout)")->capture_default_str();
  c->callback([] { std::exit(compare(cmp)); });

  static GenerateOptions gen;
  auto* g = pg->add_subcommand("generate",
                               "Synthetic Manhattan world (thesis §3.3.1): a robot on a grid of streets, odometry and loop\n"
                               "closures to earlier visits with Gaussian noise, the guess dead reckoning. The same seed gives the\n"
                               "same file on any machine.");
  g->add_option("--world", gen.world, "manhattan")->capture_default_str();
  g->add_option("--nodes", gen.manhattan.nodes, "Poses")->capture_default_str();
  g->add_option("--seed", gen.manhattan.seed, "Random seed")->capture_default_str();
  g->add_option("--out", gen.out, "g2o file to write")->required();
  g->add_option("--truth-out", gen.truth_out, "Also write the noise-free poses (simulated truth) with the same edges");
  g->add_option("--side", gen.manhattan.side, "Streets per side (0: about 9 visits a spot)")->capture_default_str();
  g->add_option("--closure-probability", gen.manhattan.closure_probability, "Per earlier visit of a spot")->capture_default_str();
  g->callback([] { std::exit(generate(gen)); });
}

}  // namespace trailnav::cli
