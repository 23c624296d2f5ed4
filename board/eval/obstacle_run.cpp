#include "obstacle_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <unordered_set>

#include "figure.hpp"
#include "png.hpp"
#include "revolution_source.hpp"
#include "trailnav/perception/ground_height.hpp"
#include "trailnav/perception/terrain_mapper.hpp"
#include "sim_truth.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "world.hpp"

namespace trailnav::eval {

namespace fs = std::filesystem;
namespace vel = trailnav::velodyne;
using perception::FusionModel;
using perception::ObstacleMap;

ClassCells MapScore::all_free() const noexcept {
  ClassCells c;
  for (const ClassCells& k : classes) {
    c.free += k.free;
    c.fake += k.fake;
  }
  return c;
}

namespace {

using SteadyClock = std::chrono::steady_clock;
double ms_since(SteadyClock::time_point t0) {
  return std::chrono::duration<double, std::milli>(SteadyClock::now() - t0).count();
}

// The truth on the obstacle map's cells: what each cell holds, its terrain
// class and whether it lies next to something that is not free ground.
class TruthCells {
 public:
  TruthCells(const SimTruth& truth, double res, int tolerance) : res_(res) {
    const TruthRaster& o = truth.obstacles;
    const double rr = o.resolution;
    ix0_ = static_cast<std::int32_t>(std::floor((o.x0 - 0.5 * rr) / res));
    iy0_ = static_cast<std::int32_t>(std::floor((o.y0 - 0.5 * rr) / res));
    nx_ = static_cast<std::int32_t>(std::floor((o.x0 + (o.width - 0.5) * rr) / res)) - ix0_ + 1;
    ny_ = static_cast<std::int32_t>(std::floor((o.y0 + (o.height - 0.5) * rr) / res)) - iy0_ + 1;
    const auto n = static_cast<std::size_t>(nx_) * static_cast<std::size_t>(ny_);
    code_.assign(n, 0);
    cls_.assign(n, 255);
    near_.assign(n, 0);
    outline_.assign(n, 0);
    sighted_.assign(truth.sightings.empty() ? 0 : n, 0);
    side_hit_.assign(truth.side_hits.empty() ? 0 : n, 0);
    side_sighted_.assign(truth.side_sightings.empty() ? 0 : n, 0);
    std::vector<std::array<std::uint16_t, perception::kTerrainClasses>> counts(n);
    for (int j = 0; j < o.height; ++j) {
      for (int i = 0; i < o.width; ++i) {
        const double px = o.x0 + i * rr, py = o.y0 + j * rr;
        const std::size_t k = index(static_cast<std::int32_t>(std::floor(px / res)), static_cast<std::int32_t>(std::floor(py / res)));
        const std::size_t src = static_cast<std::size_t>(j) * static_cast<std::size_t>(o.width) + static_cast<std::size_t>(i);
        const std::uint8_t c = std::min<std::uint8_t>(o.data[src], 3);
        if (sim::truth_rank(c) > sim::truth_rank(code_[k])) code_[k] = c;
        if (o.data[src] == 1) {
          earliest(truth.sightings, sighted_, src, k);
          earliest(truth.side_hits, side_hit_, src, k);
          earliest(truth.side_sightings, side_sighted_, src, k);
        }
        const std::uint8_t t = truth.terrain.data[src];
        if (t < perception::kTerrainClasses) ++counts[k][t];
      }
    }
    for (std::size_t k = 0; k < n; ++k) {
      const auto& c = counts[k];
      const auto best = std::max_element(c.begin(), c.end());
      if (*best > 0) cls_[k] = static_cast<std::uint8_t>(best - c.begin());
    }
    // A solid obstacle's outline: its cells with a 4-neighbour that is not
    // part of a solid obstacle. Only there does the height step; a flat top
    // is as flat as a road to any geometric detector.
    auto solid = [&](std::int32_t x, std::int32_t y) {
      return x >= 0 && y >= 0 && x < nx_ && y < ny_ && code_[local(x, y)] == 1;
    };
    for (std::int32_t y = 0; y < ny_; ++y) {
      for (std::int32_t x = 0; x < nx_; ++x) {
        if (solid(x, y) && !(solid(x - 1, y) && solid(x + 1, y) && solid(x, y - 1) && solid(x, y + 1))) {
          outline_[local(x, y)] = 1;
        }
      }
    }
    for (std::int32_t y = 0; y < ny_; ++y) {
      for (std::int32_t x = 0; x < nx_; ++x) {
        if (code_[local(x, y)] == 0) continue;
        for (std::int32_t dy = -tolerance; dy <= tolerance; ++dy) {
          for (std::int32_t dx = -tolerance; dx <= tolerance; ++dx) {
            if (x + dx >= 0 && x + dx < nx_ && y + dy >= 0 && y + dy < ny_) near_[local(x + dx, y + dy)] = 1;
          }
        }
      }
    }
  }

  bool contains(std::int32_t wx, std::int32_t wy) const noexcept {
    return wx >= ix0_ && wy >= iy0_ && wx < ix0_ + nx_ && wy < iy0_ + ny_;
  }
  std::size_t index(std::int32_t wx, std::int32_t wy) const noexcept { return local(wx - ix0_, wy - iy0_); }
  std::uint8_t code(std::size_t k) const noexcept { return code_[k]; }
  std::uint8_t cls(std::size_t k) const noexcept { return cls_[k]; }
  bool near(std::size_t k) const noexcept { return near_[k] != 0; }
  bool outline(std::size_t k) const noexcept { return outline_[k] != 0; }
  bool has_sightings() const noexcept { return !sighted_.empty(); }
  // Has a lidar return come from the solid obstacle in this cell by `ms` after the start?
  bool sighted(std::size_t k, std::int64_t ms) const noexcept { return by(sighted_, k, ms); }
  bool has_side_sightings() const noexcept { return !side_sighted_.empty(); }
  // ... from one of its sides within 20 m, grazing or clipping the top edge included?
  bool side_hit(std::size_t k, std::int64_t ms) const noexcept { return by(side_hit_, k, ms); }
  // ... from one of its sides, showing the face (board/sim/truth.hpp)?
  bool side_sighted(std::size_t k, std::int64_t ms) const noexcept { return by(side_sighted_, k, ms); }
  // When (ms after the start) a side was first seen there; 0: never.
  std::uint32_t side_sighted_ms(std::size_t k) const noexcept { return side_sighted_[k]; }
  double resolution() const noexcept { return res_; }

 private:
  std::size_t local(std::int32_t x, std::int32_t y) const noexcept {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(nx_) + static_cast<std::size_t>(x);
  }
  double res_;
  std::int32_t ix0_ = 0, iy0_ = 0, nx_ = 0, ny_ = 0;
  std::vector<std::uint8_t> code_, cls_, near_, outline_;
  std::vector<std::uint32_t> sighted_, side_hit_, side_sighted_;

  // Was the cell's first return of that kind (ms after the start + 1; 0: never) by `ms`?
  static bool by(const std::vector<std::uint32_t>& first, std::size_t k, std::int64_t ms) noexcept {
    return !first.empty() && first[k] != 0 && static_cast<std::int64_t>(first[k]) <= ms + 1;
  }
  // A truth pixel's first sighting into its map cell: the earliest of its pixels'.
  static void earliest(const std::vector<std::uint32_t>& pixels, std::vector<std::uint32_t>& cells, std::size_t src,
                       std::size_t k) noexcept {
    if (pixels.empty() || pixels[src] == 0) return;
    std::uint32_t& first = cells[k];
    first = first == 0 ? pixels[src] : std::min(first, pixels[src]);
  }
};

struct NamedShape {
  std::string name;
  double x, y, radius;
};

std::vector<NamedShape> named_obstacles(const sim::Scenario& s) {
  std::vector<NamedShape> out;
  for (const sim::Obstacle& o : s.obstacles) {
    double r = 0.0;
    const char* kind = "";
    switch (o.type) {
      case sim::ObstacleType::box: r = 0.5 * std::hypot(o.size.x(), o.size.y()); kind = "box"; break;
      case sim::ObstacleType::pole: r = o.radius; kind = "pole"; break;
      case sim::ObstacleType::tree: r = o.radius; kind = "trunk"; break;
      default: continue;
    }
    char name[96];
    std::snprintf(name, sizeof name, "%s at (%.1f, %.1f)", kind, o.center.x(), o.center.y());
    out.push_back({o.name.empty() ? std::string(name) : o.name, o.center.x(), o.center.y(), r});
  }
  return out;
}

class Scorer {
 public:
  Scorer(const SimTruth& truth, const ObstacleRunOptions& o, double res)
      : truth_(truth), cells_(truth, res, o.tolerance_cells), radius_(o.score_radius), tolerance_(o.tolerance_cells),
        shapes_(named_obstacles(truth.scenario)), on_miss_(o.on_face_miss), on_blocked_(o.on_blocked) {}

  void init(MapScore& s) const {
    for (const NamedShape& n : shapes_) s.named.push_back({n.name, 0, 0, {}});
  }

  void score(const ObstacleMap& map, double rx, double ry, std::int64_t t_ns, MapScore& s) {
    const auto& g = map.grid();
    const double res = g.resolution();
    const CellIndex c = g.world_to_index(rx, ry);
    // The snapshot's time since the recording's start, as the truth rasters count it.
    const std::int64_t ms = (t_ns - truth_.scenario.start_utc_ns) / 1'000'000;
    const auto r = static_cast<std::int32_t>(std::ceil(radius_ / res));
    auto occupied = [&](std::int32_t x, std::int32_t y) {
      const CellIndex i{x, y};
      return g.contains(i) && map.state(g.at(i)) == perception::CellState::occupied;
    };
    for (std::int32_t dy = -r; dy <= r; ++dy) {
      for (std::int32_t dx = -r; dx <= r; ++dx) {
        if (dx * dx + dy * dy > r * r) continue;
        const std::int32_t x = c.x + dx, y = c.y + dy;
        if (!cells_.contains(x, y) || !g.contains({x, y})) continue;
        const perception::ObstacleCell& cell = g.at({x, y});
        if (!cell.known()) continue;
        const std::size_t k = cells_.index(x, y);
        const std::uint8_t code = cells_.code(k);
        if (code == 0) {
          if (cells_.near(k) || cells_.cls(k) >= perception::kTerrainClasses) continue;
          ClassCells& cc = s.classes[cells_.cls(k)];
          ++cc.free;
          if (map.state(cell) == perception::CellState::occupied) ++cc.fake;
          continue;
        }
        // A solid obstacle counts once the lidar has seen it (simulated
        // recordings say when), not when grass around it was seen.
        if (code == 1 && cells_.has_sightings() && !cells_.sighted(k, ms)) continue;
        FoundCells& f = code == 1 ? s.obstacles : code == 2 ? s.negative : s.vegetation;
        ++f.cells;
        bool found = false;
        for (std::int32_t ty = -tolerance_; ty <= tolerance_ && !found; ++ty) {
          for (std::int32_t tx = -tolerance_; tx <= tolerance_ && !found; ++tx) found = occupied(x + tx, y + ty);
        }
        if (found) ++f.found;
        if (code != 1 || !cells_.outline(k)) continue;
        ++s.outlines.cells;
        if (found) ++s.outlines.found;
        if (cells_.side_hit(k, ms)) {
          ++s.faces_hit.cells;
          if (found) ++s.faces_hit.found;
        }
        // Of the outline, the cells where the lidar has seen a side of the
        // obstacle: a step the geometry can show (a box's back edge seen
        // only on its top cannot).
        if (!cells_.has_side_sightings() || !cells_.side_sighted(k, ms)) continue;
        ++s.faces.cells;
        if (found) ++s.faces.found;
        const double wx = (x + 0.5) * res, wy = (y + 0.5) * res;
        std::size_t named = shapes_.size();
        for (std::size_t n = 0; n < shapes_.size(); ++n) {
          if (std::hypot(shapes_[n].x - wx, shapes_[n].y - wy) > shapes_[n].radius + res) continue;
          ++s.named[n].faces.cells;
          if (found) ++s.named[n].faces.found;
          named = n;
          break;
        }
        auto& found_once = found_once_[static_cast<std::size_t>(map.model())];
        if (found) {
          found_once.insert(k);
          continue;
        }
        const bool lost = found_once.count(k) != 0;
        if (lost) ++s.faces_lost;
        if (!on_miss_) continue;
        FaceMiss miss;
        miss.model = map.model();
        miss.time_s = 1e-3 * static_cast<double>(ms);
        miss.robot_x = rx;
        miss.robot_y = ry;
        miss.x = wx;
        miss.y = wy;
        miss.distance = std::hypot(wx - rx, wy - ry);
        miss.side_seen_s = 1e-3 * cells_.side_sighted_ms(k);
        if (named < shapes_.size()) miss.obstacle = shapes_[named].name;
        miss.probability = map.probability(cell);
        miss.found_before = lost;
        on_miss_(miss);
      }
    }
    // Fake obstacles on the robot's next 4 m of true path, within 0.3 m of it.
    const auto& traj = truth_.trajectory;
    auto it = std::lower_bound(traj.begin(), traj.end(), t_ns, [](const TruthPose& p, std::int64_t t) { return p.utc_ns < t; });
    bool blocked = false;
    double travelled = 0.0, since_check = 1e9;
    const auto rr = static_cast<std::int32_t>(std::ceil(0.3 / res));
    for (auto p = it; p != traj.end() && travelled < 4.0 && !blocked; ++p) {
      if (p != it) {
        const double step = std::hypot(p->x - (p - 1)->x, p->y - (p - 1)->y);
        travelled += step;
        since_check += step;
      }
      if (since_check < 0.1) continue;
      since_check = 0.0;
      const CellIndex pc = g.world_to_index(p->x, p->y);
      for (std::int32_t dy = -rr; dy <= rr && !blocked; ++dy) {
        for (std::int32_t dx = -rr; dx <= rr && !blocked; ++dx) {
          if (dx * dx + dy * dy > rr * rr) continue;
          const std::int32_t x = pc.x + dx, y = pc.y + dy;
          if (!cells_.contains(x, y)) continue;
          const std::size_t k = cells_.index(x, y);
          if (cells_.code(k) == 0 && !cells_.near(k) && occupied(x, y)) {
            blocked = true;
            if (on_blocked_) {
              BlockedPath b;
              b.model = map.model();
              b.time_s = 1e-3 * static_cast<double>(ms);
              b.robot_x = rx;
              b.robot_y = ry;
              b.x = (x + 0.5) * res;
              b.y = (y + 0.5) * res;
              b.ahead = travelled;
              b.truth_class = static_cast<perception::TerrainClass>(cells_.cls(k));
              b.probability = map.probability(g.at({x, y}));
              on_blocked_(b);
            }
          }
        }
      }
    }
    ++s.snapshots;
    if (blocked) ++s.blocked;
    // Named obstacles within the radius: any occupied cell on them?
    for (std::size_t n = 0; n < shapes_.size(); ++n) {
      const NamedShape& sh = shapes_[n];
      if (std::hypot(sh.x - rx, sh.y - ry) > radius_) continue;
      ++s.named[n].snapshots;
      const CellIndex oc = g.world_to_index(sh.x, sh.y);
      const auto rr2 = static_cast<std::int32_t>(std::ceil((sh.radius + res) / res));
      bool hit = false;
      for (std::int32_t dy = -rr2; dy <= rr2 && !hit; ++dy) {
        for (std::int32_t dx = -rr2; dx <= rr2 && !hit; ++dx) {
          const std::int32_t x = oc.x + dx, y = oc.y + dy;
          if (!cells_.contains(x, y)) continue;
          if (cells_.code(cells_.index(x, y)) == 1 && occupied(x, y)) hit = true;
        }
      }
      if (hit) ++s.named[n].detected;
    }
  }

 private:
  const SimTruth& truth_;
  TruthCells cells_;
  double radius_;
  int tolerance_;
  std::vector<NamedShape> shapes_;
  std::function<void(const FaceMiss&)> on_miss_;
  std::function<void(const BlockedPath&)> on_blocked_;
  std::array<std::unordered_set<std::size_t>, perception::kFusionModels> found_once_;  // face cells found at some snapshot, per map
};

// Mean per-cell KL(P || Q) in bits over the cells P has observed.
double mean_kl(const ObstacleMap& p_map, const ObstacleMap& q_map) {
  const auto& gp = p_map.grid();
  const auto& gq = q_map.grid();
  const CellIndex o = gp.origin();
  double sum = 0.0;
  std::uint64_t n = 0;
  for (std::int32_t y = 0; y < gp.size_y(); ++y) {
    for (std::int32_t x = 0; x < gp.size_x(); ++x) {
      const perception::ObstacleCell& a = gp.at({o.x + x, o.y + y});
      if (!a.known() || !gq.contains({o.x + x, o.y + y})) continue;
      const perception::ObstacleCell& b = gq.at({o.x + x, o.y + y});
      const double p = static_cast<double>(perception::logistic(a.logit));
      const double q = static_cast<double>(perception::logistic(b.logit));
      sum += p * std::log2(p / q) + (1.0 - p) * std::log2((1.0 - p) / (1.0 - q));
      ++n;
    }
  }
  return n ? sum / static_cast<double>(n) : 0.0;
}


// The points of the revolution just processed that lie in the box, with the
// class the map update fused them with and what the class's models say.
void report_points(const perception::ObstaclePipeline& pipeline, const perception::TerrainClassMap* classes,
                   const std::array<double, 4>& box, std::uint64_t revolution, std::int64_t first_ns,
                   const std::function<void(const PointRecord&)>& out) {
  const perception::RevolutionCloud& c = pipeline.cloud();
  const perception::TerrainSource terrain = pipeline.terrain_source(classes);
  PointRecord r;
  r.time_s = static_cast<double>(c.time_ns - first_ns) * 1e-9;
  r.revolution = revolution;
  for (int ring = 0; ring < c.rings(); ++ring) {
    for (int col = 0; col < c.columns(); ++col) {
      const std::size_t k = c.index(ring, col);
      if (c.state[k] == perception::PointState::none) continue;
      r.x = c.ref_x + static_cast<double>(c.x[k]);
      r.y = c.ref_y + static_cast<double>(c.y[k]);
      if (r.x < box[0] || r.x > box[1] || r.y < box[2] || r.y > box[3]) continue;
      r.z = c.ref_z + static_cast<double>(c.z[k]);
      r.ring = ring;
      r.column = col;
      r.range = c.range[k];
      r.state = c.state[k];
      const bool measured = r.state == perception::PointState::measured;
      r.step_height = measured ? c.step_height[k] : 0.0f;
      r.sin_incline = measured ? c.sin_incline[k] : 0.0f;
      const perception::ObstaclePipeline::PointAnswer a = pipeline.answer(terrain, k);
      r.terrain = a.terrain;
      r.terrain_known = a.terrain_known;
      r.dirac = a.dirac;
      r.smooth = a.smooth;
      out(r);
    }
  }
}

}  // namespace

Status write_obstacle_png(const std::string& path, const ObstacleMap& map, double robot_x, double robot_y,
                          const std::string& title, const std::vector<std::string>& notes) {
  const auto& g = map.grid();
  const auto w = static_cast<std::uint32_t>(g.size_x());
  const auto h = static_cast<std::uint32_t>(g.size_y());
  constexpr cli::Rgb kUnknown{60, 70, 90}, kRobot{230, 30, 30};
  // Free white to black by P(obstacle); cells the map calls occupied tinted blue.
  const auto color = [](float p, bool occupied) {
    const auto v = static_cast<std::uint8_t>(std::lround(255.0f * (1.0f - p)));
    if (occupied) return cli::Rgb{static_cast<std::uint8_t>(v / 2), static_cast<std::uint8_t>(v / 2), v};
    return cli::Rgb{v, v, v};
  };
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  const CellIndex o = g.origin();
  std::uint64_t occupied = 0, known = 0;
  for (std::uint32_t row = 0; row < h; ++row) {
    const auto y = static_cast<std::int32_t>(h - 1 - row);  // north up
    for (std::uint32_t col = 0; col < w; ++col) {
      const perception::ObstacleCell& c = g.at({o.x + static_cast<std::int32_t>(col), o.y + y});
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + col) * 3];
      cli::Rgb k = kUnknown;
      if (c.known()) {
        ++known;
        const bool occ = map.state(c) == perception::CellState::occupied;
        occupied += occ ? 1 : 0;
        k = color(perception::logistic(c.logit), occ);
      }
      px[0] = k.r, px[1] = k.g, px[2] = k.b;
    }
  }
  const CellIndex rc = g.world_to_index(robot_x, robot_y);
  for (int dy = -3; dy <= 3; ++dy) {
    for (int dx = -3; dx <= 3; ++dx) {
      if (dx * dx + dy * dy > 9) continue;
      const int col = rc.x + dx - o.x;
      const int row = static_cast<int>(h) - 1 - (rc.y + dy - o.y);
      if (col < 0 || row < 0 || col >= static_cast<int>(w) || row >= static_cast<int>(h)) continue;
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(row) * w + static_cast<std::size_t>(col)) * 3];
      px[0] = kRobot.r, px[1] = kRobot.g, px[2] = kRobot.b;
    }
  }
  cli::MapFigure figure;
  figure.title = title;
  figure.notes = notes;
  char text[128];
  std::snprintf(text, sizeof text, "%u x %u cells of %.2f m; %llu seen, %llu occupied", w, h, g.resolution(),
                static_cast<unsigned long long>(known), static_cast<unsigned long long>(occupied));
  figure.notes.emplace_back(text);
  figure.legend = {{kUnknown, "unknown (not seen)"},
                   {color(0.0f, false), "free, P = 0"},
                   {color(0.5f, false), "P = 0.5"},
                   {color(0.75f, true), "occupied, P = 0.75"},
                   {color(1.0f, true), "occupied, P = 1"},
                   {kRobot, "robot"}};
  figure.metres_per_pixel = g.resolution();
  return cli::write_map_figure(path, rgb, static_cast<int>(w), static_cast<int>(h), figure);
}

std::string_view answer_code_name(AnswerCode c) noexcept {
  switch (c) {
    case AnswerCode::evaluated: return "evaluated";
    case AnswerCode::cell_shared: return "its cell's answer";
    case AnswerCode::no_return: return "no return";
    case AnswerCode::not_placed: return "not placed";
    case AnswerCode::apart_in_cell: return "apart in its cell";
    case AnswerCode::out_of_range: return "out of range";
    case AnswerCode::vehicle: return "the vehicle";
    case AnswerCode::dropped: return "dropped in alignment";
    case AnswerCode::isolated: return "isolated";
    case AnswerCode::ground_only: return "by its height above the ground";
  }
  return "?";
}

void answer_scan_points(const cloud::PointCloud& c, std::span<const cloud::PointPlace> places,
                        const perception::ObstaclePipeline& pipeline, const perception::TerrainClassMap* classes,
                        std::vector<ScanPointAnswer>& out) {
  const std::vector<std::int32_t>& fates = pipeline.point_fates();
  const perception::TerrainSource terrain = pipeline.terrain_source(classes);
  const bool dirac = pipeline.config().model == FusionModel::pw;
  const auto stride = static_cast<std::size_t>(pipeline.cloud().stride());
  if (out.size() != c.size) out.resize(c.size);
  constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
  const perception::RevolutionCloud& cloud = pipeline.cloud();
  const perception::PointState* state = cloud.state.data();
  const float* step = cloud.step_height.data();
  const float* sine = cloud.sin_incline.data();
  const float* height = pipeline.ground_height().empty() ? nullptr : pipeline.ground_height().data();
  auto from_fate = [&](std::int32_t fate, ScanPointAnswer& a) {
    a.probability = kNan;
    if (fate >= 0) {
      const auto k = static_cast<std::size_t>(fate);
      const perception::PointState st = state[k];
      if (st == perception::PointState::measured || st == perception::PointState::flat) {
        const auto ans = pipeline.answer(terrain, k);
        a.probability = ans.smooth;
        a.step_height = step[k];
        a.sin_incline = sine[k];
        if (height != nullptr) a.height = height[k];
        a.obstacle = (dirac ? ans.dirac : ans.smooth > 0.5f) ? 1 : 0;
        return;
      }
      a.code = AnswerCode::isolated;
      return;
    }
    a.code = fate == perception::kFateOutOfRange ? AnswerCode::out_of_range
             : fate == perception::kFateSelf     ? AnswerCode::vehicle
             : fate == perception::kFateNoReturn ? AnswerCode::no_return
                                                 : AnswerCode::dropped;
  };
  // A point alignment did not take (a second one apart in its cell, a
  // third one): by its height above the ground alone, when the ground is
  // on. Into the cloud's frame as alignment takes its cell's points (the
  // transform of the column it fired in).
  const perception::GroundGrid* ground = pipeline.ground();
  auto by_ground = [&](std::size_t i, const cloud::PointPlace& p, AnswerCode otherwise, ScanPointAnswer& a) {
    a.probability = kNan;
    a.code = otherwise;
    if (ground == nullptr) return;
    const perception::RevolutionCloud::Point q = pipeline.cloud().to_reference(p.column, c.x[i], c.y[i], c.z[i]);
    const float g = ground->ground_at(q.x, q.y);
    if (std::isnan(g)) return;
    const float h = q.z - g;
    const bool up = pipeline.config().ground.raise && h > pipeline.config().ground.height;
    const auto ans = pipeline.answer_at(terrain, q.x, q.y, up ? h : 0.0f, up ? 1.0f : 0.0f);
    a.code = AnswerCode::ground_only;
    a.height = h;
    a.probability = ans.smooth;
    a.obstacle = (dirac ? ans.dirac : ans.smooth > 0.5f) ? 1 : 0;
  };
  for (std::size_t i = 0; i < c.size && i < places.size(); ++i) {
    const cloud::PointPlace& p = places[i];
    ScanPointAnswer& a = out[i];
    a = ScanPointAnswer{};
    const std::size_t cell = static_cast<std::size_t>(p.row) * stride + p.column;
    switch (p.outcome) {
      case cloud::PlaceOutcome::placed:
        a.code = AnswerCode::evaluated;
        from_fate(fates[cell], a);
        break;
      case cloud::PlaceOutcome::second: {
        if (p.apart <= kSharedCellGap) {
          a.code = AnswerCode::cell_shared;
          from_fate(fates[cell], a);
        } else {
          by_ground(i, p, AnswerCode::apart_in_cell, a);
        }
        break;
      }
      case cloud::PlaceOutcome::collision:
        by_ground(i, p, AnswerCode::not_placed, a);
        break;
      case cloud::PlaceOutcome::invalid:
        a.code = AnswerCode::no_return;
        a.probability = kNan;
        break;
      case cloud::PlaceOutcome::bad_ring:
        a.code = AnswerCode::not_placed;
        a.probability = kNan;
        break;
    }
  }
}

ObstacleRunReport run_obstacles(const ObstacleRunOptions& options) {
  ObstacleRunReport report;
  auto opened = RevolutionSource::open(options.inputs, options.calibration, options.cloud);
  if (!opened.source) {
    report.error = opened.error;
    return report;
  }
  RevolutionSource& source = *opened.source;
  report.input_kind = source.input_kind();
  report.model_name = source.model_name();
  const std::optional<SimTruth>& truth = source.truth();
  perception::ObstacleConfig config = options.config;
  if (!config.features.self_box && source.self_box()) {
    config.features.self_box = source.self_box();
    report.source_self_box = config.features.self_box;
  }
  if (truth && config.mount.translation == std::array<double, 3>{0.0, 0.0, 0.0}) config.mount.translation = source.mount_translation();
  if (options.terrain == TerrainMode::truth && !truth) {
    report.error = "--terrain truth needs a simulated recording (a directory with truth/)";
    return report;
  }
  if (!options.out_dir.empty()) {
    std::error_code ec;
    fs::create_directories(options.out_dir, ec);
    if (ec) {
      report.error = "cannot create " + options.out_dir + ": " + ec.message();
      return report;
    }
  }
  const vel::RangeImageShape shape = source.shape();

  config.compare_models = config.compare_models || truth.has_value();
  auto made = perception::ObstaclePipeline::create(config, shape);
  if (!made.pipeline) {
    report.error = made.error;
    return report;
  }
  perception::ObstaclePipeline& pipeline = *made.pipeline;
  const bool answers = options.on_scan_answers && source.scan_cloud() != nullptr;
  // A point-cloud file has no pose stream: its points go straight into the
  // pipeline, unless something reads the range images.
  const bool direct = source.scan_cloud() != nullptr && !options.through_range_images &&
                      options.terrain != TerrainMode::estimated && !options.on_revolution;
  source.take_scans_without_images(direct);
  if (answers) pipeline.keep_point_fates();
  std::vector<ScanPointAnswer> scan_answers;

  std::optional<perception::PoseTrack> poses;
  if (truth && options.truth_poses) {
    poses.emplace(truth->trajectory.size() + 1);
    fill_pose_track(*truth, *poses);
  }
  std::optional<perception::TerrainClassMap> terrain;
  if (options.terrain == TerrainMode::truth) terrain.emplace();
  // Estimated classes: the terrain analysis runs on the same revolutions, in
  // step with the obstacle pipeline (offline there is no second thread, so
  // the result does not depend on timing).
  std::unique_ptr<perception::TerrainMapper> mapper;
  if (options.terrain == TerrainMode::estimated) {
    if (options.terrain_forest == nullptr) {
      report.error = "estimated terrain classes need a terrain model";
      return report;
    }
    if (std::string e = perception::check_forest_lidar(*options.terrain_forest, source.lidar_model(), options.terrain_forest_name);
        !e.empty()) {
      report.error = e;
      return report;
    }
    if (std::string e = perception::check_forest_settings(*options.terrain_forest, options.terrain_config,
                                                          options.terrain_forest_name);
        !e.empty()) {
      report.error = e;
      return report;
    }
    auto made_mapper = perception::TerrainMapper::create(options.terrain_config, config.mount, shape, options.terrain_forest,
                                                         config.features);
    if (!made_mapper.mapper) {
      report.error = "terrain: " + made_mapper.error;
      return report;
    }
    mapper = std::move(made_mapper.mapper);
  }
  std::optional<Scorer> scorer;
  if (truth) {
    scorer.emplace(*truth, options, config.map.resolution);
    report.scored = true;
    report.side_sightings = !truth->side_sightings.empty();
    for (int m = 0; m < perception::kFusionModels; ++m) {
      if (pipeline.map(static_cast<FusionModel>(m)) != nullptr) {
        report.scores[static_cast<std::size_t>(m)].emplace();
        scorer->init(*report.scores[static_cast<std::size_t>(m)]);
      }
    }
  }
  const bool compare = pipeline.map(FusionModel::pw) && pipeline.map(FusionModel::ps) && pipeline.map(FusionModel::pc);
  if (compare) report.kl.emplace();

  double align_ms = 0.0, features_ms = 0.0, map_ms = 0.0, terrain_ms = 0.0;
  auto write_pngs = [&](const std::string& suffix) {
    if (options.out_dir.empty()) return;
    for (int m = 0; m < perception::kFusionModels; ++m) {
      const ObstacleMap* map = pipeline.map(static_cast<FusionModel>(m));
      if (map == nullptr) continue;
      const std::string name = "obstacles-" + std::string(perception::fusion_model_name(static_cast<FusionModel>(m))) + suffix;
      const std::string png = (fs::path(options.out_dir) / (name + ".png")).string();
      char note[96];
      std::snprintf(note, sizeof note, "after revolution %llu", static_cast<unsigned long long>(report.revolutions));
      if (write_obstacle_png(png, *map, pipeline.cloud().robot_x, pipeline.cloud().robot_y,
                             "obstacle map, fusion " + std::string(perception::fusion_model_name(static_cast<FusionModel>(m))),
                             {note})) {
        report.files.push_back(png);
      }
    }
  };
  std::int64_t first_ns = 0;  // PointRecord::time_s counts from here
  auto on_image = [&](const vel::RangeImage& image) {
    if (options.max_revolutions > 0 && report.revolutions >= static_cast<std::uint64_t>(options.max_revolutions)) return false;
    ++report.revolutions;
    if (options.on_revolution) options.on_revolution(image);
    auto t0 = SteadyClock::now();
    if (direct) {
      pipeline.align_scan(*source.scan_cells());
    } else {
      pipeline.align(image, poses ? &*poses : nullptr);
    }
    align_ms += ms_since(t0);
    t0 = SteadyClock::now();
    pipeline.features();
    features_ms += ms_since(t0);
    if (terrain) {
      terrain->grid().move_to(pipeline.cloud().robot_x, pipeline.cloud().robot_y);
      fill_truth_terrain(*truth, *terrain);
    }
    const perception::TerrainClassMap* classes = terrain ? &*terrain : nullptr;
    if (mapper) {
      t0 = SteadyClock::now();
      mapper->process(image, poses ? &*poses : nullptr);
      terrain_ms += ms_since(t0);
      if (mapper->map().sequence > 0) classes = &mapper->map();
    }
    t0 = SteadyClock::now();
    pipeline.update_maps(classes);
    map_ms += ms_since(t0);
    if (options.on_processed) options.on_processed(pipeline);
    if (answers) {
      answer_scan_points(*source.scan_cloud(), source.scan_places(), pipeline, classes, scan_answers);
      options.on_scan_answers(ScanAnswers{source.scan_file(), *source.scan_cloud(), scan_answers});
    }
    if (options.points_box && options.on_point) {
      if (first_ns == 0) first_ns = truth ? truth->scenario.start_utc_ns : pipeline.cloud().time_ns;
      report_points(pipeline, classes, *options.points_box, report.revolutions, first_ns, options.on_point);
    }
    const auto rev = report.revolutions;
    if (scorer && options.score_every > 0 && rev % static_cast<std::uint64_t>(options.score_every) == 0) {
      for (int m = 0; m < perception::kFusionModels; ++m) {
        const ObstacleMap* map = pipeline.map(static_cast<FusionModel>(m));
        if (map != nullptr) {
          scorer->score(*map, pipeline.cloud().robot_x, pipeline.cloud().robot_y, pipeline.cloud().time_ns,
                        *report.scores[static_cast<std::size_t>(m)]);
        }
      }
    }
    if (compare && options.score_every > 0 && rev % static_cast<std::uint64_t>(options.score_every) == 0) {
      const double pw = mean_kl(*pipeline.map(FusionModel::pc), *pipeline.map(FusionModel::pw));
      const double ps = mean_kl(*pipeline.map(FusionModel::pc), *pipeline.map(FusionModel::ps));
      KlSummary& k = *report.kl;
      k.mean_pw += pw;
      k.mean_ps += ps;
      k.max_pw = std::max(k.max_pw, pw);
      k.max_ps = std::max(k.max_ps, ps);
      ++k.snapshots;
    }
    if (options.png_every > 0 && rev % static_cast<std::uint64_t>(options.png_every) == 0) {
      char suffix[32];
      std::snprintf(suffix, sizeof suffix, "-%06llu", static_cast<unsigned long long>(rev));
      write_pngs(suffix);
    }
    return true;
  };

  if (std::string error = source.run(on_image, options.progress); !error.empty()) {
    report.error = error;
    return report;
  }
  report.malformed_packets = source.malformed_packets();
  report.cloud_points = source.cloud_totals();

  write_pngs("");
  if (!options.out_dir.empty()) {
    // Raw probabilities of the configured model: float32, row-major from the
    // map's origin (row 0 = lowest y), NaN for unknown; described in a YAML file.
    const ObstacleMap& map = pipeline.map();
    const auto& g = map.grid();
    std::vector<float> probs(g.cell_count());
    const CellIndex o = g.origin();
    for (std::int32_t y = 0; y < g.size_y(); ++y) {
      for (std::int32_t x = 0; x < g.size_x(); ++x) {
        probs[static_cast<std::size_t>(y) * static_cast<std::size_t>(g.size_x()) + static_cast<std::size_t>(x)] =
            map.probability(g.at({o.x + x, o.y + y}));
      }
    }
    const std::string raw = (fs::path(options.out_dir) / "obstacles.f32").string();
    if (std::FILE* f = std::fopen(raw.c_str(), "wb")) {
      std::fwrite(probs.data(), sizeof(float), probs.size(), f);
      std::fclose(f);
      report.files.push_back(raw);
    }
    const std::string meta = (fs::path(options.out_dir) / "obstacles.yaml").string();
    if (std::FILE* f = std::fopen(meta.c_str(), "w")) {
      std::fprintf(f,
                   "# trailnav obstacles: the last obstacle map of model %s\n"
                   "file: obstacles.f32   # float32 little-endian P(obstacle), NaN = never observed\n"
                   "width: %d\nheight: %d\nresolution: %.4f\n"
                   "origin: [%.4f, %.4f]   # odometry-frame x, y of the lower-left corner of cell (0, 0)\n"
                   "rows: south_up   # row 0 is the lowest y\n"
                   "revolutions: %llu\nrobot: [%.4f, %.4f, %.5f]   # x, y, yaw at the last revolution\n",
                   std::string(perception::fusion_model_name(map.model())).c_str(), g.size_x(), g.size_y(),
                   g.resolution(), o.x * g.resolution(), o.y * g.resolution(),
                   static_cast<unsigned long long>(report.revolutions), pipeline.cloud().robot_x,
                   pipeline.cloud().robot_y, pipeline.cloud().robot_yaw);
      std::fclose(f);
      report.files.push_back(meta);
    }
  }
  if (report.kl && report.kl->snapshots > 0) {
    report.kl->mean_pw /= static_cast<double>(report.kl->snapshots);
    report.kl->mean_ps /= static_cast<double>(report.kl->snapshots);
  }
  report.counters = pipeline.counters();
  if (mapper) report.terrain_steps = mapper->counters().steps;
  if (report.revolutions > 0) {
    const auto n = static_cast<double>(report.revolutions);
    report.align_ms = align_ms / n;
    report.features_ms = features_ms / n;
    report.map_ms = map_ms / n;
    report.terrain_ms = terrain_ms / n;
  }
  return report;
}

}  // namespace trailnav::eval
