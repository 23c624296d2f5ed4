#include "trailnav/navigation/slam/g2o_io.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

namespace trailnav::slam {
namespace {

constexpr std::size_t kMaxTokens = 32;  // EDGE_SE3:QUAT: tag, 2 ids, 7 pose, 21 information

struct Tokens {
  std::array<std::string_view, kMaxTokens> token;
  std::size_t count = 0;
  bool overflow = false;
};

Tokens split(std::string_view line) {
  Tokens t;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    if (i >= line.size()) break;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (t.count == kMaxTokens) {
      t.overflow = true;
      break;
    }
    t.token[t.count++] = line.substr(i, j - i);
    i = j;
  }
  return t;
}

struct Parser {
  const std::string& name;
  std::size_t line = 0;
  std::string error;

  bool fail(const std::string& what) {
    error = name + ":" + std::to_string(line) + ": " + what;
    return false;
  }
  bool number(std::string_view s, double& out, const char* what) {
    const char* end = s.data() + s.size();
    auto [p, ec] = std::from_chars(s.data(), end, out);
    if (ec != std::errc() || p != end) return fail(std::string(what) + " '" + std::string(s) + "' is not a number");
    if (!std::isfinite(out)) return fail(std::string(what) + " '" + std::string(s) + "' is not finite");
    return true;
  }
  bool integer(std::string_view s, std::int64_t& out, const char* what) {
    const char* end = s.data() + s.size();
    auto [p, ec] = std::from_chars(s.data(), end, out);
    if (ec != std::errc() || p != end) return fail(std::string(what) + " '" + std::string(s) + "' is not a whole number");
    return true;
  }
};

struct PendingEdge {
  std::int64_t from = 0, to = 0;
  std::size_t line = 0;
};

template <int N>
bool positive_definite(const Eigen::Matrix<double, N, N>& m) {  // m symmetric by construction
  Eigen::LLT<Eigen::Matrix<double, N, N>> llt(m);
  return llt.info() == Eigen::Success;
}

// Reads the upper triangle, row by row (g2o's order), into a symmetric matrix.
template <int N>
Eigen::Matrix<double, N, N> upper_to_symmetric(const double* v) {
  Eigen::Matrix<double, N, N> m;
  int k = 0;
  for (int r = 0; r < N; ++r) {
    for (int c = r; c < N; ++c) {
      m(r, c) = v[k];
      m(c, r) = v[k];
      ++k;
    }
  }
  return m;
}

bool quaternion(Parser& p, double qx, double qy, double qz, double qw, Eigen::Quaterniond& out) {
  const double n = std::sqrt(qx * qx + qy * qy + qz * qz + qw * qw);
  if (std::abs(n - 1.0) > 1e-3) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "the quaternion's norm is %.6g, not 1 (within 1e-3)", n);
    return p.fail(buf);
  }
  // A quaternion written from a unit one reads back with the same bits.
  const double k = std::abs(n - 1.0) <= 4e-16 ? 1.0 : 1.0 / n;
  out = Eigen::Quaterniond(qw * k, qx * k, qy * k, qz * k);
  return true;
}

}  // namespace

const char* graph_kind_name(GraphKind k) noexcept {
  switch (k) {
    case GraphKind::none: return "none";
    case GraphKind::planar: return "SE(2)";
    case GraphKind::spatial: return "SE(3)";
  }
  return "?";
}

namespace {

// The parser proper: `next_line` hands out the lines one by one (false at
// the end), so a file is read as a stream and never held whole.
template <class NextLine>
G2oReadResult read_lines(NextLine&& next_line, const std::string& name, GraphCapacity capacity, G2oGraph& out) {
  G2oReadResult result;
  out.kind = GraphKind::none;
  out.planar.clear();
  out.spatial.clear();
  Parser p{name, 0, {}};
  std::vector<PendingEdge> pending;
  pending.reserve(capacity.edges);
  std::vector<std::pair<std::int64_t, std::size_t>> fixes;  // id, line
  auto kind = [&](GraphKind k) {
    if (out.kind == GraphKind::none) {
      out.kind = k;
      if (k == GraphKind::spatial) {
        out.spatial.reserve(capacity);
      } else {
        out.planar.reserve(capacity);
      }
    }
    if (out.kind != k) {
      return p.fail(std::string("a ") + graph_kind_name(k) + " element in a file of " + graph_kind_name(out.kind) +
                    " elements: one file holds one kind");
    }
    return true;
  };
  auto expect = [&](const Tokens& t, std::size_t numbers) {
    if (t.overflow || t.count != numbers + 1) {
      return p.fail(std::string(t.token[0]) + " takes " + std::to_string(numbers) + " fields after the tag, found " +
                    (t.overflow ? std::string("more than ") + std::to_string(kMaxTokens - 1) : std::to_string(t.count - 1)));
    }
    return true;
  };
  std::array<double, kMaxTokens> v{};
  auto numbers = [&](const Tokens& t, std::size_t first, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) {
      if (!p.number(t.token[first + i], v[i], "field")) return false;
    }
    return true;
  };
  auto vertex_full = [&] { return p.fail("more vertices than the capacity of " + std::to_string(capacity.vertices)); };
  auto edge_full = [&] { return p.fail("more edges than the capacity of " + std::to_string(capacity.edges)); };

  std::string_view line;
  while (next_line(line)) {
    ++p.line;
    const Tokens t = split(line);
    if (t.count == 0 || t.token[0][0] == '#') continue;
    const std::string_view tag = t.token[0];
    if (tag == "VERTEX_SE2") {
      std::int64_t id = 0;
      if (!kind(GraphKind::planar) || !expect(t, 4) || !p.integer(t.token[1], id, "vertex id") || !numbers(t, 2, 3)) break;
      if (!out.planar.add_vertex(id, Se2{v[0], v[1], wrap_angle(v[2])})) {
        vertex_full();
        break;
      }
    } else if (tag == "VERTEX_SE3:QUAT") {
      std::int64_t id = 0;
      if (!kind(GraphKind::spatial) || !expect(t, 8) || !p.integer(t.token[1], id, "vertex id") || !numbers(t, 2, 7)) break;
      Se3 x;
      x.t = Eigen::Vector3d(v[0], v[1], v[2]);
      if (!quaternion(p, v[3], v[4], v[5], v[6], x.q)) break;
      if (!out.spatial.add_vertex(id, x)) {
        vertex_full();
        break;
      }
    } else if (tag == "EDGE_SE2") {
      PendingEdge pe{0, 0, p.line};
      if (!kind(GraphKind::planar) || !expect(t, 11) || !p.integer(t.token[1], pe.from, "vertex id") ||
          !p.integer(t.token[2], pe.to, "vertex id") || !numbers(t, 3, 9)) {
        break;
      }
      GraphEdge<Se2> e;
      e.measurement = Se2{v[0], v[1], wrap_angle(v[2])};
      e.information = upper_to_symmetric<3>(v.data() + 3);
      if (!positive_definite<3>(e.information)) {
        p.fail("the information matrix is not positive definite");
        break;
      }
      if (!out.planar.add_edge(e)) {
        edge_full();
        break;
      }
      pending.push_back(pe);
    } else if (tag == "EDGE_SE3:QUAT") {
      PendingEdge pe{0, 0, p.line};
      if (!kind(GraphKind::spatial) || !expect(t, 30) || !p.integer(t.token[1], pe.from, "vertex id") ||
          !p.integer(t.token[2], pe.to, "vertex id") || !numbers(t, 3, 28)) {
        break;
      }
      GraphEdge<Se3> e;
      e.measurement.t = Eigen::Vector3d(v[0], v[1], v[2]);
      if (!quaternion(p, v[3], v[4], v[5], v[6], e.measurement.q)) break;
      e.information = upper_to_symmetric<6>(v.data() + 7);
      if (!positive_definite<6>(e.information)) {
        p.fail("the information matrix is not positive definite");
        break;
      }
      if (!out.spatial.add_edge(e)) {
        edge_full();
        break;
      }
      pending.push_back(pe);
    } else if (tag == "FIX") {
      if (t.count < 2 || t.overflow) {
        p.fail(t.overflow ? "FIX names more than " + std::to_string(kMaxTokens - 1) + " vertices on one line"
                          : std::string("FIX names no vertex"));
        break;
      }
      bool ok = true;
      for (std::size_t i = 1; i < t.count && ok; ++i) {
        std::int64_t id = 0;
        ok = p.integer(t.token[i], id, "vertex id");
        if (ok) fixes.emplace_back(id, p.line);
      }
      if (!ok) break;
    } else {
      p.fail("'" + std::string(tag) +
             "' is not read by trailnav (VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT and FIX are)");
      break;
    }
  }
  result.lines = p.line;
  if (!p.error.empty()) {
    result.error = p.error;
    return result;
  }
  // Resolve ids to indices.
  const std::size_t n = out.vertex_count();
  std::vector<std::pair<std::int64_t, std::int32_t>> index;
  index.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t id = out.kind == GraphKind::spatial ? out.spatial.id(i) : out.planar.id(i);
    index.emplace_back(id, static_cast<std::int32_t>(i));
  }
  std::sort(index.begin(), index.end());
  for (std::size_t i = 1; i < index.size(); ++i) {
    if (index[i].first == index[i - 1].first) {
      result.error = name + ": vertex " + std::to_string(index[i].first) + " is given twice";
      return result;
    }
  }
  auto find = [&](std::int64_t id) -> std::int32_t {
    auto it = std::lower_bound(index.begin(), index.end(), std::make_pair(id, std::int32_t{-1}));
    return it != index.end() && it->first == id ? it->second : -1;
  };
  for (std::size_t e = 0; e < pending.size(); ++e) {
    const std::int32_t a = find(pending[e].from), b = find(pending[e].to);
    p.line = pending[e].line;
    if (a < 0 || b < 0) {
      p.fail("the edge names vertex " + std::to_string(a < 0 ? pending[e].from : pending[e].to) + ", which the file never gives");
      break;
    }
    if (a == b) {
      p.fail("the edge joins vertex " + std::to_string(pending[e].from) + " to itself");
      break;
    }
    if (out.kind == GraphKind::spatial) {
      auto& edge = out.spatial.edge(e);
      edge.from = a;
      edge.to = b;
    } else {
      auto& edge = out.planar.edge(e);
      edge.from = a;
      edge.to = b;
    }
  }
  for (const auto& [id, fix_line] : fixes) {
    if (!p.error.empty()) break;
    const std::int32_t a = find(id);
    p.line = fix_line;
    if (a < 0) {
      p.fail("FIX names vertex " + std::to_string(id) + ", which the file never gives");
      break;
    }
    if (out.kind == GraphKind::spatial) {
      out.spatial.set_fixed(static_cast<std::size_t>(a), true);
    } else {
      out.planar.set_fixed(static_cast<std::size_t>(a), true);
    }
  }
  if (!p.error.empty()) {
    result.error = p.error;
    return result;
  }
  if (out.kind == GraphKind::none) {
    result.error = name + ": no vertex and no edge in the file";
    return result;
  }
  result.ok = true;
  return result;
}

}  // namespace

G2oReadResult read_g2o(std::string_view text, const std::string& name, GraphCapacity capacity, G2oGraph& out) {
  std::size_t pos = 0;
  auto next_line = [&](std::string_view& line) {
    if (pos >= text.size()) return false;
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    line = text.substr(pos, end - pos);
    pos = end + 1;
    return true;
  };
  return read_lines(next_line, name, capacity, out);
}

G2oReadResult read_g2o_file(const std::string& path, GraphCapacity capacity, G2oGraph& out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    G2oReadResult r;
    r.error = path + ": cannot open for reading";
    return r;
  }
  std::string buffer;
  auto next_line = [&](std::string_view& line) {
    if (!std::getline(in, buffer)) return false;
    line = buffer;
    return true;
  };
  G2oReadResult r = read_lines(next_line, path, capacity, out);
  if (r.ok && in.bad()) {
    r.ok = false;
    r.error = path + ": read error after line " + std::to_string(r.lines);
  }
  return r;
}

G2oCounts count_g2o_file(const std::string& path) {
  G2oCounts c;
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    c.error = path + ": cannot open for reading";
    return c;
  }
  std::string line;
  while (std::getline(in, line)) {
    std::size_t i = 0;
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    if (line.compare(i, 7, "VERTEX_") == 0) ++c.vertices;
    if (line.compare(i, 5, "EDGE_") == 0) ++c.edges;
  }
  c.ok = !in.bad();
  if (!c.ok) c.error = path + ": read error";
  return c;
}

namespace {

void put(std::string& s, double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, " %.17g", v);
  s += buf;
}

}  // namespace

std::string write_g2o(const PoseGraph2d& g) {
  std::string s;
  s.reserve(g.vertex_count() * 60 + g.edge_count() * 200);
  for (std::size_t i = 0; i < g.vertex_count(); ++i) {
    s += "VERTEX_SE2 " + std::to_string(g.id(i));
    put(s, g.pose(i).x);
    put(s, g.pose(i).y);
    put(s, g.pose(i).theta);
    s += '\n';
  }
  for (const auto& e : g.edges()) {
    s += "EDGE_SE2 " + std::to_string(g.id(static_cast<std::size_t>(e.from))) + " " +
         std::to_string(g.id(static_cast<std::size_t>(e.to)));
    put(s, e.measurement.x);
    put(s, e.measurement.y);
    put(s, e.measurement.theta);
    for (int r = 0; r < 3; ++r) {
      for (int c = r; c < 3; ++c) put(s, e.information(r, c));
    }
    s += '\n';
  }
  for (std::size_t i = 0; i < g.vertex_count(); ++i) {
    if (g.fixed(i)) s += "FIX " + std::to_string(g.id(i)) + "\n";
  }
  return s;
}

std::string write_g2o(const PoseGraph3d& g) {
  std::string s;
  s.reserve(g.vertex_count() * 120 + g.edge_count() * 500);
  auto pose = [&](const Se3& x) {
    put(s, x.t.x());
    put(s, x.t.y());
    put(s, x.t.z());
    put(s, x.q.x());
    put(s, x.q.y());
    put(s, x.q.z());
    put(s, x.q.w());
  };
  for (std::size_t i = 0; i < g.vertex_count(); ++i) {
    s += "VERTEX_SE3:QUAT " + std::to_string(g.id(i));
    pose(g.pose(i));
    s += '\n';
  }
  for (const auto& e : g.edges()) {
    s += "EDGE_SE3:QUAT " + std::to_string(g.id(static_cast<std::size_t>(e.from))) + " " +
         std::to_string(g.id(static_cast<std::size_t>(e.to)));
    pose(e.measurement);
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c) put(s, e.information(r, c));
    }
    s += '\n';
  }
  for (std::size_t i = 0; i < g.vertex_count(); ++i) {
    if (g.fixed(i)) s += "FIX " + std::to_string(g.id(i)) + "\n";
  }
  return s;
}

std::string write_g2o(const G2oGraph& graph) {
  return graph.kind == GraphKind::spatial ? write_g2o(graph.spatial) : write_g2o(graph.planar);
}

}  // namespace trailnav::slam
