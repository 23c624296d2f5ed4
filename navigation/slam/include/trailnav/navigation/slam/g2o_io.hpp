// g2o's text format for pose graphs: VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT,
// EDGE_SE3:QUAT and FIX lines ('#' comments and blank lines skipped). One
// file holds one kind (planar or spatial). Every malformed line is an error
// naming the file and line and what is wrong; nothing is guessed:
//   - a line with too few or too many numbers, a number that does not parse
//     or is not finite;
//   - an element trailnav does not read (landmarks, offsets, ...);
//   - a vertex id given twice, an edge or FIX naming a vertex never given,
//     an edge from a vertex to itself;
//   - an information matrix that is not symmetric positive definite;
//   - a quaternion whose norm is not within 1 ± 1e-3 (rounded files are
//     normalised; anything farther is not a rotation);
//   - planar and spatial elements mixed; more vertices or edges than the
//     capacity the caller sized the graph for.
// Writing keeps 17 significant digits: a graph written and read back is the
// same bits.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

#include "trailnav/navigation/slam/pose_graph.hpp"

namespace trailnav::slam {

enum class GraphKind { none, planar, spatial };
const char* graph_kind_name(GraphKind k) noexcept;

struct G2oGraph {
  GraphKind kind = GraphKind::none;
  PoseGraph2d planar;
  PoseGraph3d spatial;
  std::size_t vertex_count() const noexcept {
    return kind == GraphKind::spatial ? spatial.vertex_count() : planar.vertex_count();
  }
  std::size_t edge_count() const noexcept { return kind == GraphKind::spatial ? spatial.edge_count() : planar.edge_count(); }
  double chi2() const noexcept { return kind == GraphKind::spatial ? spatial.chi2() : planar.chi2(); }
};

struct G2oReadResult {
  bool ok = false;
  std::string error;  // "FILE:LINE: what" when not ok
  std::size_t lines = 0;
};

// Parses `text` (named `name` in errors) into `out`, whose graphs are reserved
// for `capacity` first (the storage of both kinds: only the kind read is used).
G2oReadResult read_g2o(std::string_view text, const std::string& name, GraphCapacity capacity, G2oGraph& out);
// Reads the file at `path`, line by line (never held whole).
G2oReadResult read_g2o_file(const std::string& path, GraphCapacity capacity, G2oGraph& out);

// How many vertices and edges a file holds (lines starting VERTEX_ and
// EDGE_), to size a graph for it before reading it.
struct G2oCounts {
  bool ok = false;
  std::string error;
  std::size_t vertices = 0, edges = 0;
};
G2oCounts count_g2o_file(const std::string& path);

std::string write_g2o(const PoseGraph2d& graph);
std::string write_g2o(const PoseGraph3d& graph);
std::string write_g2o(const G2oGraph& graph);

}  // namespace trailnav::slam
